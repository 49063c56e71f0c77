"""Benchmark: 2-byte reads through dynamixel-sdk over the pty, against references measured in the same run.

Prints, for each configuration, reads per second and p50/p99 latency, then
ratios against two references taken on this machine in this run:

* a bare pty responder (a few lines that answer every 8-byte read with a
  fixed reply): the ceiling any emulator can reach here;
* the wire limit: a 2-byte READ is 8 bytes out and 8 back, 10 bits each,
  so 160 bit-times per read (6,250 reads/s at 1 Mbps).

Goals: at Return Delay Time 0, >= 80 % of the bare responder's
rate with p99 < 1 ms; Return Delay Time 250 adds 500 +/- 50 us per read;
with ``--pace`` the rate matches the wire limit within 5 %.  For ``--pace`` the
emulator's own part of each read (from the instruction's arrival to the
reply's last byte, read from its ``--trace``) is printed beside the rate the
client sees, which also carries the client's own time per transaction.

The RDT 0 comparison alternates between the bare responder and the two
emulators in 0.2 s turns (the others stopped meanwhile), because this shared
machine's speed drifts by tens of percent within a minute: measured one after
the other, the same program scored anywhere from 64 % to 96 % of the bare rate.

``--web`` measures only what the live view costs the bus: one moving servo
at Return Delay Time 0, served with and without ``--web`` while a WebSocket
client (its own process, as a browser would be) streams the page's frames,
interleaved the same way; goal: >= 90 % of the rate without, with >= 20
frames/s reaching the client.

``--web chromium`` opens the page itself in headless Chromium instead (the
page draws every frame, as a tester's browser would; on a two-core machine its
drawing competes with the bus for the processor).

``--protocol 2.0`` measures a robot's Protocol 2.0 control cycle instead: through dynamixel-sdk's
PacketHandler(2.0), a GroupSyncRead of Present Position from six X-series servos and a
GroupSyncWrite of their Goal Positions, at Return Delay Time 0, against ``ax12emu serve --servo
MODEL --ids 1-6`` and a bare Protocol 2.0 responder (a few lines answering each Sync Read with six
fixed status packets at once and staying silent on the Sync Write), alternated in the same 0.2 s
turns; goal: >= 80 % of the bare rate.  The goals change every 500 cycles; the same loop with new goals
every cycle, as a streamed trajectory sends them, is measured after it for information.  Served without
``--pace``, as here, bytes take no time: the
six status packets go out in list order, each Return Delay Time (0) after the one before it, so
together, as the bare responder's do (``merge_replies(in_sequence=True)``); with ``--pace`` each
would wait until the one before it had left the wire (150 us each at 1 Mbps).

Usage: ``python tools/bench_protocol.py [--seconds 2] [--rounds 3] [--web [socket|chromium]] [--protocol 2.0 [--model M]]``
"""

from __future__ import annotations

import os
import select
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from dynamixel_sdk import COMM_RX_CORRUPT, COMM_SUCCESS, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

from ax12emu.cli.arg_types import OneLineParser, positive_float, positive_int
from ax12emu.protocol.servo_models import model as servo_model
from ax12emu.protocol.servo_models import model_names

#: What ``--model`` may name: the Protocol 2.0 loop reads and writes the X series' control table (Present
#: Position at 132), which an XL-320's or a Protocol 1.0 model's is not; another would fail only once served.
X_MODELS = tuple(k for k in model_names() if servo_model(k).protocols == ("2.0",) and servo_model(k).classic is None)

#: Per byte written into the EEPROM area, how long to leave the servo alone (about 6 ms measured, 9 ms by the datasheet).
EEPROM_WAIT_S = 0.009

BARE_RESPONDER = textwrap.dedent(
    """
    import os, pty, select, sys, tty
    master, slave = pty.openpty()
    tty.setraw(slave)
    print(os.ttyname(slave), flush=True)
    reply = bytes([0xFF, 0xFF, 1, 4, 0, 0, 2, 0xF8])
    pending = b""
    while True:
        select.select([master], [], [])
        pending += os.read(master, 4096)
        while len(pending) >= 8:
            pending = pending[8:]
            os.write(master, reply)
    """
)


#: The Protocol 2.0 counterpart: answers each Sync Read (instruction 0x82) with the status packets
#: given in hex as its argument, all at once, and stays silent on every other packet (a Sync Write).
BARE_RESPONDER2 = textwrap.dedent(
    """
    import os, pty, select, sys, tty
    master, slave = pty.openpty()
    tty.setraw(slave)
    print(os.ttyname(slave), flush=True)
    reply = bytes.fromhex(sys.argv[1])
    pending = b""
    while True:
        select.select([master], [], [])
        pending += os.read(master, 4096)
        while len(pending) >= 8 and len(pending) >= 7 + pending[5] + 256 * pending[6]:
            if pending[7] == 0x82:
                os.write(master, reply)
            pending = pending[7 + pending[5] + 256 * pending[6]:]
    """
)


def start(command: list[str]) -> tuple[subprocess.Popen, str]:
    """Start a server process and read the port path it prints first."""
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    ready, _, _ = select.select([process.stdout], [], [], 20)
    if not ready:
        process.kill()
        raise RuntimeError(f"{command} printed no port")
    return process, process.stdout.readline().strip()


def stop(process: subprocess.Popen) -> None:
    """Terminate by pid and reap."""
    process.terminate()
    try:
        process.wait(5)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


class Session:
    """An open dynamixel-sdk port on one server, running one transaction in timed runs.

    ``transaction(port, ph)`` builds the transaction: a callable that runs it once and returns
    the SDK's result code; by default a read of Present Position of ID 1 (Protocol 1.0).
    """

    def __init__(self, path: str, *, baud: int = 1_000_000, setup=None, protocol: float = 1.0,
                 transaction=None) -> None:
        self.port = PortHandler(path)
        self.port.openPort()
        self.port.setBaudRate(baud)
        self.ph = PacketHandler(protocol)
        if setup:
            setup(self.port, self.ph)
        if transaction is None:
            self.transaction = read_present_position(self.port, self.ph)
        else:
            self.transaction = transaction(self.port, self.ph)
        self.latencies: list[float] = []
        self.failures = 0
        self.elapsed_s = 0.0
        #: CPU seconds the server used during the timed runs, where the caller measures it.
        self.server_cpu_s = 0.0
        self.warm_up(200)

    def warm_up(self, count: int) -> None:
        """Untimed transactions (the first ones after a pause pay for catching up)."""
        for _ in range(count):
            self.transaction()

    def run(self, seconds: float) -> None:
        """Run the transaction as fast as possible for ``seconds``, adding to the totals."""
        transaction, latencies = self.transaction, self.latencies
        start_s = time.perf_counter()
        end = start_s + seconds
        while True:
            t0 = time.perf_counter()
            if t0 >= end:
                break
            comm = transaction()
            latencies.append(time.perf_counter() - t0)
            self.failures += comm != COMM_SUCCESS
        self.elapsed_s += time.perf_counter() - start_s

    def result(self) -> dict:
        """Rate and latency over every run so far."""
        self.port.closePort()
        latencies = sorted(self.latencies)
        return {
            "rate": len(latencies) / self.elapsed_s,
            "p50_us": latencies[len(latencies) // 2] * 1e6,
            "p99_us": latencies[int(len(latencies) * 0.99)] * 1e6,
            "failures": self.failures,
            "count": len(latencies),
            "server_cpu_s": self.server_cpu_s,
        }


def read_present_position(port: PortHandler, ph: PacketHandler):
    """The default transaction: a 2-byte read of ID 1's Present Position, returning the SDK's result code.

    Why the guard: dynamixel-sdk's read2ByteTxRx indexes the reply's data whenever the packet it
    took was well formed, so a stale or short status packet (a late answer to a read that had
    timed out, on a loaded machine) raises IndexError instead of returning an error code.  The
    benchmark counts it as the failed read it is rather than stopping the run.
    """
    read = ph.read2ByteTxRx

    def once() -> int:
        try:
            return read(port, 1, 36)[1]
        except IndexError:
            return COMM_RX_CORRUPT

    return once


def measure(path: str, seconds: float, *, baud: int = 1_000_000, setup=None) -> dict:
    """Read Present Position of ID 1 as fast as possible for ``seconds``; rate and latency."""
    session = Session(path, baud=baud, setup=setup)
    session.run(seconds)
    return session.result()


def measure_interleaved(targets: dict[str, tuple[subprocess.Popen, Session]], seconds: float,
                        slice_s: float = 0.2, spans: dict | None = None) -> dict[str, dict]:
    """Each target ``seconds`` in all, in turns of ``slice_s``, the others stopped (SIGSTOP) meanwhile.

    Why: this machine's speed drifts by tens of percent within a minute, so
    configurations measured one after the other are not comparable; in short
    alternating slices every one sees the same machine.  A stopped server uses
    no CPU; a resumed emulator catches its physics up first, which the untimed
    reads after resuming absorb (that burst is an artefact of the stop, not of
    serving).  ``spans``, if given, gets each target's running turns as
    (start, end) pairs on the monotonic clock.
    """
    processes = [process for process, _ in targets.values()]
    for process in processes:
        process.send_signal(signal.SIGSTOP)
    try:
        for _ in range(max(1, round(seconds / slice_s))):
            for name, (process, session) in targets.items():
                process.send_signal(signal.SIGCONT)
                begin_s = time.monotonic()
                session.warm_up(50)
                cpu_before_s = cpu_s(process.pid)
                session.run(slice_s)
                session.server_cpu_s += cpu_s(process.pid) - cpu_before_s
                process.send_signal(signal.SIGSTOP)
                if spans is not None:
                    spans.setdefault(name, []).append((begin_s, time.monotonic()))
    finally:
        for process in processes:
            process.send_signal(signal.SIGCONT)
    return {name: session.result() for name, (_, session) in targets.items()}


def configure(rdt: int, ids: list[int], moving: bool, baud_value: int | None = None):
    """A setup callback: Return Delay Time on every servo, optionally wheel-mode motion and a baud change."""

    def setup(port: PortHandler, ph: PacketHandler) -> None:
        for servo_id in ids:
            ph.write1ByteTxRx(port, servo_id, 5, rdt)
            time.sleep(EEPROM_WAIT_S)  # an AX-12 ignores packets while it writes its EEPROM
            if moving:
                ph.write4ByteTxRx(port, servo_id, 6, 0)  # both angle limits 0: wheel mode
                time.sleep(4 * EEPROM_WAIT_S)
                ph.write1ByteTxRx(port, servo_id, 24, 1)
                ph.write2ByteTxRx(port, servo_id, 32, 300 + servo_id)
        if baud_value is not None:
            for servo_id in ids:
                ph.write1ByteTxOnly(port, servo_id, 4, baud_value)
            time.sleep(0.05)

    return setup


#: X-series control table (ROBOTIS e-manual, XL430-W250): Return Delay Time, Torque Enable, Goal and
#: Present Position.
X_RETURN_DELAY_TIME, X_TORQUE_ENABLE, X_GOAL_POSITION, X_PRESENT_POSITION = 9, 64, 116, 132
#: The Protocol 2.0 loop's servos: one leg's worth, as a robot's control cycle reads and drives them.
SYNC_IDS = list(range(1, 7))
#: Cycles between swaps of the two sets of Goal Positions, so the servos keep moving.
GOAL_SWAP_CYCLES = 500


def configure2(port: PortHandler, ph: PacketHandler) -> None:
    """Return Delay Time 0 and torque on, on every servo of the Protocol 2.0 loop."""
    for servo_id in SYNC_IDS:
        ph.write1ByteTxRx(port, servo_id, X_RETURN_DELAY_TIME, 0)
        time.sleep(EEPROM_WAIT_S)
        ph.write1ByteTxRx(port, servo_id, X_TORQUE_ENABLE, 1)


def streamed_sync_cycle(port: PortHandler, ph: PacketHandler):
    """:func:`sync_cycle` with new Goal Positions every cycle, as a streamed trajectory sends them (the
    client's ``changeParam`` inside the cycle, for the bare responder and the emulator alike)."""
    read = GroupSyncRead(port, ph, X_PRESENT_POSITION, 4)
    write = GroupSyncWrite(port, ph, X_GOAL_POSITION, 4)
    for servo_id in SYNC_IDS:
        read.addParam(servo_id)
        write.addParam(servo_id, [0, 0, 0, 0])
    cycles = 0

    def cycle() -> int:
        nonlocal cycles
        cycles += 1
        comm = read.txRxPacket()
        goal = 1024 + 3 * cycles % 2048  # a new goal each cycle, the servos moving across the range
        for servo_id in SYNC_IDS:
            write.changeParam(servo_id, list((goal + 50 * servo_id).to_bytes(4, "little")))
        written = write.txPacket()
        return comm if comm != COMM_SUCCESS else written

    return cycle


def sync_cycle(port: PortHandler, ph: PacketHandler):
    """A control cycle: GroupSyncRead of every servo's Present Position, then GroupSyncWrite of Goal Positions.

    Only the transactions are timed: the client's own work on the answers (getData) is left out, so
    the emulator's share of each cycle is as large as the loop can make it.
    """
    read = GroupSyncRead(port, ph, X_PRESENT_POSITION, 4)
    for servo_id in SYNC_IDS:
        read.addParam(servo_id)
    writes = []
    for goal in (1024, 3072):
        write = GroupSyncWrite(port, ph, X_GOAL_POSITION, 4)
        for servo_id in SYNC_IDS:
            write.addParam(servo_id, list((goal + 50 * servo_id).to_bytes(4, "little")))
        writes.append(write)
    cycles = 0

    def cycle() -> int:
        nonlocal cycles
        cycles += 1
        comm = read.txRxPacket()
        written = writes[cycles // GOAL_SWAP_CYCLES % 2].txPacket()
        return comm if comm != COMM_SUCCESS else written

    return cycle


def bare_sync_reply() -> bytes:
    """The status packets the bare Protocol 2.0 responder answers every Sync Read with."""
    from ax12emu.protocol.packets2 import encode_status2

    return b"".join(encode_status2(servo_id, 0, (2048).to_bytes(4, "little")) for servo_id in SYNC_IDS)


def compare_interleaved(servers: list[tuple[object, list[str], dict]], seconds: float) -> dict[str, dict]:
    """Start each (name, command, Session keywords) server, measure them in alternating turns, stop them."""
    processes = []
    try:
        targets = {}
        for name, command, session in servers:
            process, path = start(command)
            processes.append(process)
            targets[name] = (process, Session(path, **session))
        return measure_interleaved(targets, seconds)
    finally:
        for process in processes:
            stop(process)


def measure_protocol2(emulator: list[str], model: str, seconds: float) -> None:
    """The Protocol 2.0 loop against a bare responder and ``ax12emu serve --servo MODEL``, in alternating turns:
    the goal's loop (:func:`sync_cycle`), then, for information, the same with new goals every cycle."""
    what = f"GroupSyncRead + GroupSyncWrite x {len(SYNC_IDS)}, RDT 0"
    for transaction, how in ((sync_cycle, f"goals swapped every {GOAL_SWAP_CYCLES} cycles"),
                             (streamed_sync_cycle, "new goals every cycle")):
        loop = {"protocol": 2.0, "transaction": transaction}
        with tempfile.TemporaryDirectory() as tmp:
            script = Path(tmp, "bare2.py")
            script.write_text(BARE_RESPONDER2)
            result = compare_interleaved([
                ("bare", [sys.executable, str(script), bare_sync_reply().hex()], loop),
                ("emulator", emulator + ["--servo", model, "--ids", f"1-{len(SYNC_IDS)}", "--baud", "1000000"],
                 {**loop, "setup": configure2}),
            ], seconds)
        bare, emulated = result["bare"], result["emulator"]
        print(f"-- {how}")
        print(row("reference: bare Protocol 2.0 responder", bare))
        warn_if_loaded(bare)
        print(row(f"ax12emu --servo {model}", emulated, bare["rate"]))
        goal = " (goal >= 80 %)" if transaction is sync_cycle else " (for information)"
        print(f"{what}, {how}: {emulated['rate'] / bare['rate']:.1%} of bare{goal}, p99 {emulated['p99_us']:.0f} us")
        # Less at the mercy of the machine's load than the rates (the physics steps and the waiting spins count too).
        print("server CPU per cycle in the timed turns: " + ", ".join(
            f"{name} {result[name]['server_cpu_s'] / result[name]['count'] * 1e6:.0f} us" for name in ("bare", "emulator")))
        print()


def warn_if_loaded(bare: dict) -> None:
    """Say so when the bare responder itself was slow: the machine is too loaded for a comparison."""
    if bare["p99_us"] >= 1000:
        print(f"warning: the bare responder's own p99 is {bare['p99_us'] / 1000:.1f} ms: this machine is too loaded "
              "for the comparison to mean much (an emulator, doing more per read, loses more); rerun when it is quieter")


def transaction_times(trace: Path) -> list[float]:
    """From an emulator trace: time from a READ's arrival to the last byte of its 8-byte reply."""
    from ax12emu.tracing.trace import IN, read_trace

    times, start_s, pending = [], None, 0
    for chunk in read_trace(trace):
        if chunk.direction == IN and len(chunk.data) == 8 and chunk.data[4] == 0x02:
            start_s, pending = chunk.t, 8
        elif start_s is not None and chunk.direction != IN:
            pending -= len(chunk.data)
            if pending <= 0:
                times.append(chunk.t - start_s)
                start_s = None
    return times[200:] or times  # skip the warm-up reads


def row(label: str, result: dict, reference: float | None = None) -> str:
    ratio = f"{result['rate'] / reference:7.1%}" if reference else "       "
    return (
        f"{label:<44} {result['rate']:9.0f}/s {ratio}  p50 {result['p50_us']:7.0f} us"
        f"  p99 {result['p99_us']:7.0f} us  failures {result['failures']}"
    )


def measure_emulator(emulator: list[str], servos: int, rdt: int, seconds: float) -> dict:
    """``servos`` servos moving, Return Delay Time ``rdt``; reads of ID 1."""
    process, path = start(emulator + ["--ids", f"1-{servos}"])
    try:
        return measure(path, seconds, setup=configure(rdt, list(range(1, servos + 1)), moving=True))
    finally:
        stop(process)


#: A live-view client in its own process (as a browser would be): reads the WebSocket and prints
#: the monotonic arrival time of every frame.
STREAM_CLIENT = textwrap.dedent(
    """
    import asyncio, sys, time
    import aiohttp

    async def main(url):
        async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
            async for message in ws:
                if message.data.startswith('{"type":"frame"'):
                    print(time.monotonic(), flush=True)

    asyncio.run(main(sys.argv[1]))
    """
)


#: The same with the page itself open in headless Chromium (Debian's, never a download): the page
#: draws every frame, as a tester's browser would.  It stops when its stdin closes, so the
#: browser is shut down by Playwright rather than orphaned.
CHROMIUM_CLIENT = textwrap.dedent(
    """
    import sys, threading, time, tempfile
    from playwright.sync_api import sync_playwright

    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync"]
    with tempfile.TemporaryDirectory() as profile, sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(profile, executable_path="/usr/bin/chromium",
                                                                headless=True, args=flags)
        page = context.new_page()
        page.on("websocket", lambda ws: ws.on("framereceived", lambda payload: print(time.monotonic(), flush=True)
                                              if str(payload).startswith('{"type":"frame"') else None))
        page.goto(sys.argv[1].replace("ws://", "http://").removesuffix("ws"))
        while not done.is_set():
            page.wait_for_timeout(100)
        context.close()
    """
)


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) a process has used so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_web(command: list[str]) -> tuple[subprocess.Popen, str, str]:
    """Start ``ax12emu serve --web``: the port (first line) and the page's URL (second line)."""
    process, path = start(command)
    return process, path, process.stdout.readline().strip()


def measure_web_cost(emulator: list[str], seconds: float, client_kind: str = "socket") -> None:
    """RDT 0 reads of one moving servo, with and without the live view open and streaming, interleaved.

    ``client_kind``: "socket" (a WebSocket client) or "chromium" (the page in headless Chromium).
    """
    processes: list[subprocess.Popen] = []
    client = None
    try:
        plain, plain_path = start(emulator + ["--ids", "1"])
        processes.append(plain)
        web, web_path, url = start_web(emulator + ["--ids", "1", "--web", "127.0.0.1:0"])
        processes.append(web)
        script = CHROMIUM_CLIENT if client_kind == "chromium" else STREAM_CLIENT
        client = subprocess.Popen([sys.executable, "-c", script, url.replace("http://", "ws://") + "ws"],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(3.0 if client_kind == "chromium" else 0.5)  # the client connects before the timing starts
        setup = configure(0, [1], moving=True)
        targets = {"plain": (plain, Session(plain_path, setup=setup)), "web": (web, Session(web_path, setup=setup))}
        spans: dict[str, list[tuple[float, float]]] = {}
        cpu_before = {name: cpu_s(process.pid) for name, (process, _) in targets.items()}
        result = measure_interleaved(targets, seconds, spans=spans)
        cpu = {name: cpu_s(process.pid) - cpu_before[name] for name, (process, _) in targets.items()}
    finally:
        if client is not None:
            client.stdin.close()  # the Chromium client closes its browser and ends
            client.stdin = None  # (communicate() below must not flush it)
            try:
                client.wait(20)
            except subprocess.TimeoutExpired:
                stop(client)
        for process in processes:
            stop(process)
    out, err = client.communicate()
    arrivals = [float(line) for line in out.split()]
    web_spans = spans.get("web", [])
    streamed_s = sum(end - begin for begin, end in web_spans)
    during = sum(any(begin <= t <= end for begin, end in web_spans) for t in arrivals)
    if not arrivals:
        print(f"the streaming client received no frames: {err.strip()[-300:]}")
    frame_hz = during / streamed_s if streamed_s else 0.0
    print(row("ax12emu, 1 servo moving, RDT 0", result["plain"]))
    what = "the page open in Chromium" if client_kind == "chromium" else "a WebSocket client streaming"
    print(row(f"the same with --web, {what}", result["web"], result["plain"]["rate"]))
    running = {name: sum(end - begin for begin, end in spans.get(name, [])) for name in cpu}
    print(
        f"live view: {frame_hz:.1f} frames/s reached the client while the emulator ran (goal >= 20); "
        f"read rate with it {result['web']['rate'] / result['plain']['rate']:.1%} of without (goal >= 90 %)"
    )
    print(
        "emulator CPU per second of its turns (both serving the same reads): "
        + ", ".join(f"{name} {cpu[name] / running[name]:.2f} s/s" for name in cpu)
        + " (the difference is the live view's own work)"
    )


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=positive_float, default=2.0, help="measuring time per configuration")
    parser.add_argument("--rounds", type=positive_int, default=3,
                        help="the RDT 0 comparison runs --seconds x --rounds per server, in 0.2 s turns (default 3)")
    parser.add_argument("--web", nargs="?", const="socket", choices=("socket", "chromium"),
                        help="only the live view's cost: reads with and without --web and a streaming client "
                             "(a WebSocket client, or the page in headless Chromium), interleaved")
    parser.add_argument("--protocol", choices=("1.0", "2.0"), default="1.0",
                        help="2.0: only the Protocol 2.0 loop (Sync Read + Sync Write of six X-series servos) "
                             "against a bare Protocol 2.0 responder, in 0.2 s turns")
    parser.add_argument("--model", default="xl430-w250", choices=X_MODELS,
                        help="with --protocol 2.0: the X-series model served")
    args = parser.parse_args(argv)
    emulator = [sys.executable, "-m", "ax12emu", "serve"]
    if args.protocol == "2.0":
        print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}, load {os.getloadavg()[0]:.1f}")
        measure_protocol2(emulator, args.model, args.seconds * args.rounds)
        return 0
    if args.web:
        print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}")
        measure_web_cost(emulator, args.seconds * args.rounds, args.web)
        return 0
    wire_1m = 1e6 / 160
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}")
    print(f"{'reference: 1 Mbps wire limit (16 bytes/read)':<44} {wire_1m:9.0f}/s")

    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp, "bare.py")
        script.write_text(BARE_RESPONDER)
        fast = compare_interleaved([
            ("bare", [sys.executable, str(script)], {}),
            (1, emulator + ["--ids", "1"], {"setup": configure(0, [1], moving=True)}),
            (18, emulator + ["--ids", "1-18"], {"setup": configure(0, list(range(1, 19)), moving=True)}),
        ], args.seconds * args.rounds)
    bare = fast.pop("bare")
    print(row("reference: bare pty responder", bare))
    warn_if_loaded(bare)
    for servos, result in fast.items():
        print(row(f"ax12emu, {servos:2d} servo(s) moving, RDT   0", result, bare["rate"]))
    slow = {}
    for servos in (1, 18):
        slow[servos] = measure_emulator(emulator, servos, 250, args.seconds)
        print(row(f"ax12emu, {servos:2d} servo(s) moving, RDT 250", slow[servos]))

    print()
    for servos in (1, 18):
        print(
            f"{servos:2d} servo(s): RDT 0 at {fast[servos]['rate'] / bare['rate']:.1%} of bare (goal >= 80 %), "
            f"p99 {fast[servos]['p99_us']:.0f} us (goal < 1000); RDT 250 adds "
            f"{slow[servos]['p50_us'] - fast[servos]['p50_us']:.0f} us at p50 (goal 500 +/- 50)"
        )

    print()
    print("--pace: rate seen by dynamixel-sdk, and the emulator's own time per read (from its --trace)")
    for baud_value, host_baud in ((1, 1_000_000), (16, 115_200), (34, 57_600)):
        servo_bps = 2_000_000 / (baud_value + 1)
        wire_s = 80 / host_baud + 80 / servo_bps
        with tempfile.TemporaryDirectory() as tmp:
            trace = Path(tmp, "pace.jsonl")
            process, path = start(emulator + ["--pace", "--trace", str(trace)])
            try:
                setup = configure(0, [1], moving=False, baud_value=None if baud_value == 1 else baud_value)
                prepare = PortHandler(path)
                prepare.openPort()
                setup(prepare, PacketHandler(1.0))
                prepare.closePort()
                result = measure(path, args.seconds, baud=host_baud)
            finally:
                stop(process)
            own_s = statistics.median(transaction_times(trace))
        print(row(f"--pace at {servo_bps:9.0f} bps (wire limit {1 / wire_s:5.0f}/s)", result, 1 / wire_s))
        print(
            f"{'':<44} emulator's own time per read: median {own_s * 1e6:7.0f} us = "
            f"{own_s / wire_s:.1%} of the wire time {wire_s * 1e6:.0f} us"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
