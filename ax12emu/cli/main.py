"""Command line: ``ax12emu serve`` (and ``python -m ax12emu``).

Why it exists: argument parsing lives in a pure :func:`parse_args` that tests
call directly; :func:`main` turns every user error (a bad flag, a bad ID
list, an unusable state file, a port in use) into one line on stderr and a
non-zero exit, never a traceback.  ``print`` is used only here: the first
line on stdout is the port to open (the pty's slave path, or the
``socket://`` URL for TCP), so scripts can read it.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ax12emu import __version__
from ax12emu.bus import Bus
from ax12emu.bus.clock import WallClock
from ax12emu.bus.state_store import StateFileError, StateStore
from ax12emu.cli import hil as cli_hil
from ax12emu.cli.arg_types import OneLineParser, file_name
from ax12emu.cli.arg_types import finite_float as _finite_float
from ax12emu.cli.arg_types import positive_float as _positive_float
from ax12emu.protocol.control_table import AX12_MODEL, DEFAULT_PROFILE, PROFILES
from ax12emu.protocol.ids import parse_ids
from ax12emu.servo.model_factory import EXTERNAL_TORQUE_MAX_NM, MODELS, ModelChoice, build_model, parse_arm
from ax12emu.servo.virtual_servo import EEPROM_BUSY_MAX_S, ServoOptions
from ax12emu.tracing.trace import TraceWriter

if TYPE_CHECKING:
    from ax12emu.serve import BusServer

__all__ = ["parse_args", "main", "build_parser"]

log = logging.getLogger("ax12emu")


def _ids(text: str) -> list[int]:
    try:
        return parse_ids(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _arm(text: str) -> tuple[float, float]:
    try:
        return parse_arm(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _external_torque(text: str) -> float:
    value = _finite_float(text)
    if not abs(value) <= EXTERNAL_TORQUE_MAX_NM:
        raise argparse.ArgumentTypeError(f"must lie in -{EXTERNAL_TORQUE_MAX_NM:.0f}..{EXTERNAL_TORQUE_MAX_NM:.0f} N m "
                                         f"(the heaviest --arm held level), got {text}")
    return value


def _eeprom_busy_ms(text: str) -> float:
    value = _finite_float(text)
    if not 0.0 <= value <= EEPROM_BUSY_MAX_S * 1e3:
        raise argparse.ArgumentTypeError(f"must lie in 0..{EEPROM_BUSY_MAX_S * 1e3:g} ms, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser for all subcommands."""
    parser = OneLineParser(prog="ax12emu", description="A virtual Dynamixel servo bus (Protocol 1.0 and 2.0).")
    parser.add_argument("--version", action="version", version=f"ax12emu {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    serve = sub.add_parser("serve", help="serve a bus of virtual servos on a pty or TCP")
    serve.add_argument("--ids", type=_ids, default=[1], metavar="LIST", help="servo IDs, e.g. 1,2,5 or 1-18 (default 1)")
    serve.add_argument(
        "--servo", metavar="SPEC",
        help="X-series servos on Protocol 2.0, or AX-18As and the MX series on Protocol 1.0: MODEL for every --ids ID "
        "(e.g. xl430-w250, ax-18a, mx-28), or IDS:MODEL,... per ID (e.g. 1-5:xm430-w350,6:xl330-m077; ax-12a, ax-18a "
        "or mx-* IDs beside them share the wire on Protocol 1.0); 'ax12emu models' lists the models",
    )
    serve.add_argument(
        "--baud", type=_positive_float, metavar="BPS",
        help="with --servo: every servo starts at this bit rate (its Baud Rate register set to the value its own model "
        "gives that rate: an MX runs up to 3000000, an AX-12A up to 2000000 (Baud Rate 0; its data sheet stops at "
        "1000000); default: each model's factory rate, "
        "57600 on the X and MX series (an MX's Baud Rate 34), 1000000 on the AX series); a servo whose EEPROM "
        "--state-dir kept starts at the rate it kept",
    )
    where = serve.add_mutually_exclusive_group()
    where.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal (the default)")
    where.add_argument("--tcp", metavar="HOST:PORT", help="serve the raw byte stream on TCP instead (PORT 0: pick one)")
    serve.add_argument("--link", metavar="PATH", help="with a pty: symlink PATH to its slave side (removed on exit)")
    serve.add_argument(
        "--allow-remote", action="store_true", help="allow --tcp and --web to bind an address other than loopback"
    )
    live = serve.add_argument_group("live view (docs: live-view.md)")
    live.add_argument(
        "--web", metavar="HOST:PORT",
        help="serve a live page of the servos on HOST:PORT (loopback; PORT 0: pick one); its URL is the second stdout line",
    )
    live.add_argument("--monitor", action="store_true", help="draw a live table of the servos on stderr")
    serve.add_argument("--state-dir", metavar="DIR", type=file_name, help="persist each servo's EEPROM area in DIR")
    serve.add_argument(
        "--factory-reset", action="store_true", help="ignore saved state and start from factory defaults"
    )
    serve.add_argument("--profile", choices=sorted(PROFILES), default=DEFAULT_PROFILE, help="control-table defaults")
    serve.add_argument("--pace", action="store_true", help="send and receive at the wire speed of the servo's baud")
    serve.add_argument("--echo", action="store_true", help="echo the host's bytes back, like a half-duplex adapter")
    serve.add_argument(
        "--time-scale", type=_positive_float, default=1.0, metavar="K", help="simulated seconds per wall second"
    )
    physics = serve.add_argument_group("model behind the servos")
    physics.add_argument("--model", choices=MODELS, default="physical", help="physical (default) or kinematic")
    physics.add_argument("--params", metavar="FILE", type=file_name,
                         help="servo parameters as TOML (e.g. from firmware_model.diagnose)")
    physics.add_argument("--voltage", type=_positive_float, metavar="V",
                         help="supply voltage (default: the AX-12A's 9.6 V, the supply its physics is fitted at; "
                              "another model's its e-manual's recommended supply)")
    physics.add_argument(
        "--controller", choices=("compliance", "pid"), default="compliance",
        help="position controller: the e-manual's compliance control (default) or the 2008 report's PID",
    )
    physics.add_argument(
        "--external-torque", type=_external_torque, default=0.0, metavar="NM", help="constant torque on every shaft, N m (+ = CCW)"
    )
    physics.add_argument("--arm", type=_arm, metavar="MASS_KG,LENGTH_M", help="an arm under gravity on every shaft")
    serve.add_argument(
        "--checksum-error",
        choices=("reply", "silent"),
        default="reply",
        help="answer a bad checksum with the Checksum Error bit (default) or stay silent",
    )
    serve.add_argument(
        "--broadcast-ping",
        choices=("reply", "silent"),
        default="reply",
        help="servos answer PING to the broadcast ID (2006 manual, default) or stay silent",
    )
    serve.add_argument(
        "--reset-reply-id",
        choices=("old", "new"),
        default="old",
        help="RESET's status packet comes from the old ID (e-manual example, default) or the new ID 1",
    )
    serve.add_argument(
        "--goal-torque",
        choices=("on", "unchanged"),
        default="on",
        help="writing Goal Position (on the AX series Moving Speed too) turns the torque on, as AX/MX users report "
        "(default), or leaves Torque Enable as it is",
    )
    serve.add_argument(
        "--eeprom-busy-ms",
        type=_eeprom_busy_ms,
        default=6.0,
        metavar="MS",
        help="after a write into the EEPROM area a servo ignores packets this long per byte written "
        "(default 6, as measured on an AX-12; 0: answer at once)",
    )
    serve.add_argument("-v", "--verbose", action="store_true", help="log every packet, one line each")
    # --trace and fault flags on serve; decode and conformance commands (cli/hil.py)
    cli_hil.add_serve_flags(serve)
    cli_hil.add_commands(sub)
    diagnose = sub.add_parser(
        "diagnose",
        add_help=False,
        help="find where a measured trace and the model disagree (python -m firmware_model.diagnose; another AX "
             "model's Wizard export starts from that servo's served model)",
    )
    diagnose.add_argument("arguments", nargs=argparse.REMAINDER)
    return parser


#: Serve options that shape some Protocol 1.0 servos only.  With --servo each applies to the servos on the wire
#: that take it (AX: the AX-12A and AX-18A; MX: the MX series) and is refused on a wire that has none of them.
#: (--trace, the live view --web --monitor and the faults, --drop --corrupt --delay --vanish --duplicate
#: --alarm --stall, serve every servo.)
_APPLIES_TO = {"params": ("AX",), "model": ("AX",), "controller": ("AX",), "reset_reply_id": ("AX",),
               "eeprom_busy_ms": ("AX",), "broadcast_ping": ("AX", "MX"), "goal_torque": ("AX", "MX")}
#: Serve options of the AX-12A bus that --servo does not take (yet): --arm hangs an arm on every shaft, which the
#: X-series physics does not take, and --profile picks the AX-12A table's edition.
_PROTOCOL1_ONLY = ("arm", "profile")


def _check_servo_spec(parser: argparse.ArgumentParser, args: argparse.Namespace, argv: list[str]) -> None:
    """Resolve ``--servo`` into ``args.servo_models`` [(ID, model key)], or exit with the reason."""
    from ax12emu.bus.wire import protocol1_keys, servo_family
    from ax12emu.protocol.servo_spec import parse_servo_spec

    ids_given = any(a == "--ids" or a.startswith("--ids=") for a in argv)
    try:
        args.servo_models = parse_servo_spec(args.servo, args.ids if ids_given or ":" not in args.servo else None,
                                             also=protocol1_keys())
    except ValueError as exc:
        parser.error(f"--servo: {exc}")
    defaults = parser.parse_args(["serve"])
    families = {servo_family(key) for _, key in args.servo_models}
    for dest in (*_PROTOCOL1_ONLY, *_APPLIES_TO):
        if getattr(args, dest) == getattr(defaults, dest):
            continue
        flag = "--" + dest.replace("_", "-")
        if dest in _PROTOCOL1_ONLY:
            parser.error(f"{flag} is not available with --servo yet (the AX-12A bus alone takes it)")
        if not families & set(_APPLIES_TO[dest]):
            parser.error(f"{flag} applies to {' and '.join(f'{f} series' for f in _APPLIES_TO[dest])} servos; "
                         "this --servo names none")



def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parse and cross-check arguments; errors exit through argparse with a usage line."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "serve" and args.servo is not None:
        _check_servo_spec(parser, args, sys.argv[1:] if argv is None else list(argv))
    elif args.command == "serve" and args.baud is not None:
        parser.error("--baud applies with --servo (AX-12As at another rate: --servo ax-12a --baud BPS; without it "
                     "they start at their factory 1000000)")
    if args.command == "serve":
        if args.link and args.tcp:
            parser.error("--link applies to a pty, not to --tcp")
        if args.tcp:
            from ax12emu.serve.transports.tcp import is_loopback, parse_host_port

            try:
                host, port = parse_host_port(args.tcp)
            except ValueError as exc:
                parser.error(f"--tcp: {exc}")
            if not is_loopback(host) and not args.allow_remote:
                parser.error(f"--tcp {host}: binding beyond loopback needs --allow-remote")
            args.tcp_address = (host, port)
        if args.web:
            from ax12emu.serve.transports.tcp import is_loopback, parse_host_port

            try:
                host, port = parse_host_port(args.web)
            except ValueError as exc:
                parser.error(f"--web: {exc}")
            if not is_loopback(host) and not args.allow_remote:
                parser.error(f"--web {host}: binding beyond loopback needs --allow-remote")
            args.web_address = (host, port)
    return args


#: Under --state-dir, where the Protocol 2.0 servos' files go (the AX-12As' stay at the top).
STATE_SUBDIR_2 = "protocol2"


def _ax_options(args: argparse.Namespace) -> ServoOptions:
    """The AX bus's behaviours as the serve flags set them (the AX-12A bus's, and a --servo wire's AX servos')."""
    return ServoOptions(
        profile=args.profile,
        reply_on_checksum_error=args.checksum_error == "reply",
        reply_to_broadcast_ping=args.broadcast_ping == "reply",
        reset_reply_from_new_id=args.reset_reply_id == "new",
        goal_position_enables_torque=args.goal_torque == "on",
        eeprom_busy_s_per_byte=args.eeprom_busy_ms * 1e-3,
    )


def _ax_choice(args: argparse.Namespace) -> ModelChoice:
    """The AX bus's physics as the serve flags choose it."""
    return ModelChoice(name=args.model, params_path=args.params, voltage_v=args.voltage, controller=args.controller,
                       external_torque_nm=args.external_torque, arm=args.arm, profile=args.profile)


def serve_stores(args: argparse.Namespace) -> tuple[StateStore | None, StateStore | None]:
    """The state directories ``serve --servo`` keeps each protocol's EEPROM in, claimed; (None, None) without ``--state-dir``.

    Protocol 2.0 servos keep theirs in a directory of their own: IDs are per protocol.
    """
    if not args.state_dir:
        return None, None
    return _claimed(args.state_dir), _claimed(Path(args.state_dir) / STATE_SUBDIR_2)


def build_serve_wire(args: argparse.Namespace, clock, stores: tuple[StateStore | None, StateStore | None] = (None, None)):
    """The wire ``serve --servo`` serves, built by the one builder the harness uses (:func:`ax12emu.bus.wire.build_wire_of`).

    Every servo takes ``--baud`` as its own model says its Baud Rate values (an MX runs up to 3 Mbps, an
    AX-12A not); ``ValueError`` names a servo that cannot, or a model the other flags do not fit.  ``stores``
    (:func:`serve_stores`): loaded from and saved to, each protocol's servos their own.
    """
    from ax12emu.bus.wire import build_wire_of
    from ax12emu.servo.model_factory2 import XModelChoice
    from ax12emu.servo.servo1x import Servo1XOptions
    from ax12emu.servo.servo2 import Servo2Options

    reply = args.checksum_error == "reply"
    options1 = _ax_options(args)  # --profile and --arm are refused with --servo: at their defaults here
    return build_wire_of(
        args.servo_models, clock=clock, baud_bps=args.baud,
        choice=XModelChoice(voltage_v=args.voltage, external_torque_nm=args.external_torque),
        choice1=_ax_choice(args),
        options=Servo2Options(reply_on_crc_error=reply), options1=options1,
        options1x=Servo1XOptions(reply_on_checksum_error=reply, reply_to_broadcast_ping=options1.reply_to_broadcast_ping,
                                 goal_position_enables_torque=options1.goal_position_enables_torque),
        state_store1=stores[0], state_store2=stores[1],
    )


def _serve2(args: argparse.Namespace) -> int:
    """``serve --servo``: the X series on Protocol 2.0, the AX and MX series on 1.0, or both on one wire."""
    from ax12emu.bus.wire import attach_wire_stores, save_wire_state
    from ax12emu.protocol.servo_models import model
    from ax12emu.serve import BusServer

    stores = serve_stores(args)
    # A reset run's bus gets its stores once started: a run refused before that closes its bus without saving.
    bus = build_serve_wire(args, WallClock(args.time_scale), (None, None) if args.factory_reset else stores)
    protocols = sorted({"2.0" if "2.0" in model(key).protocols else "1.0" for _, key in args.servo_models}, reverse=True)
    faults = cli_hil.fault_config(args)
    if faults.active:  # MX servos' through their firmware (Faults1X); a slot both protocols launched is refused (ValueError)
        faults.install(bus)
    # The header names every servo's model, so ax12emu decode names each ID's registers by its own table.
    servos = ",".join(f"{i}:{k}" for i, k in args.servo_models)
    trace = TraceWriter(args.trace, servos=servos) if args.trace else None
    transport = _open_transport(args)
    server = BusServer(bus, transport, pace=args.pace, echo=args.echo, trace=trace)
    live = _open_live(args, server, transport, bus)
    _stop_on_signals(server)
    if args.factory_reset:  # started: the factory image saved now, a refused run left the state alone
        attach_wire_stores(bus, *stores)
        save_wire_state(bus)
    print(transport.url, flush=True)  # the first stdout line: the port, which scripts and tests read
    if live is not None and live.url:
        print(live.url, flush=True)
    log.info("serving %s on %s (Protocol %s%s%s)", ", ".join(f"{i}:{k}" for i, k in args.servo_models), transport.name,
             "/".join(protocols), ", paced" if args.pace else "", ", echo" if args.echo else "")
    try:
        server.serve_forever()
    finally:
        if live is not None:  # first: it reads the bus through the serving thread
            live.close()
        transport.close()
        bus.close()
        if trace is not None:
            trace.close()
        log.info("stopped; %d packets served", server.packets_in)
    return 0


def _open_live(args: argparse.Namespace, server, transport, bus):
    """``--web``/``--monitor``: the live view of the served bus (AX-12s, X series or both), started; None without them.

    Without the web extra, or when the page's port is taken, the transport and the bus are closed
    before the error leaves (exit status 2 for the missing extra, with the line to install it).
    """
    if not (args.web or args.monitor):
        return None
    try:
        from ax12emu.live import LiveView

        return LiveView.for_server(
            server, seed=args.fault_seed, web=getattr(args, "web_address", None), allow_remote=args.allow_remote, monitor=args.monitor
        ).start()
    except ImportError as exc:  # the page's and the monitor's libraries load at start: the web extra
        print(f"ax12emu: --web and --monitor need the web extra: pip install 'ax12emu[web]' ({exc.__cause__ or exc})",
              file=sys.stderr)
        transport.close()
        bus.close()
        raise SystemExit(2) from None
    except OSError as exc:
        from ax12emu.serve.transports.tcp import address_error

        transport.close()
        bus.close()
        raise address_error("--web", getattr(args, "web_address", None) or ("", ""), exc) from None
    except BaseException:
        transport.close()
        bus.close()
        raise


def _claimed(directory: str | Path) -> StateStore:
    """The state directory of a serving process, taken for it alone (``StateStore.claim``); a folder it cannot
    make or write is named with the flag (the bare errno named a lock file the user never gave)."""
    try:
        store = StateStore(directory)
        store.claim()
    except OSError as exc:
        if isinstance(exc, FileExistsError):  # another server holds it: its own words name the pid
            raise
        raise OSError(exc.errno, f"--state-dir {directory}: {exc.strerror or exc}") from None
    return store


def _open_transport(args: argparse.Namespace):
    """The pty (default) or TCP transport the serve flags ask for."""
    from ax12emu.serve import open_transport
    from ax12emu.serve.transports.tcp import address_error, is_loopback

    if args.tcp:
        host, port = args.tcp_address
        try:
            transport = open_transport("tcp", host=host, port=port)
        except OSError as exc:
            raise address_error("--tcp", (host, port), exc) from None
        if not is_loopback(host):
            log.warning("serving on %s, reachable from other machines", transport.url)
        return transport
    try:
        return open_transport("pty", link=args.link)
    except OSError as exc:
        if args.link is None or isinstance(exc, FileExistsError):
            raise
        # symlink_to's error names the pty as well as the link ("'/dev/pts/0' -> '/no/dir/ax12'"): as if the pty were missing
        raise OSError(exc.errno, f"--link {args.link}: {exc.strerror or exc} (its folder must exist and be writable)") from None


def _serve(args: argparse.Namespace) -> int:
    if getattr(args, "servo_models", None):
        return _serve2(args)
    from ax12emu.serve import BusServer

    store = _claimed(args.state_dir) if args.state_dir else None
    model = build_model(_ax_choice(args), len(args.ids))
    bus = Bus(
        args.ids,
        options=_ax_options(args),
        model=model,
        clock=WallClock(args.time_scale),
        state_store=None if args.factory_reset else store,
    )
    faults = cli_hil.fault_config(args)
    if faults.active:
        faults.install(bus)
    trace = TraceWriter(args.trace, profile=args.profile) if args.trace else None
    transport = _open_transport(args)
    where = transport.url
    server = BusServer(bus, transport, pace=args.pace, echo=args.echo, trace=trace)
    live = _open_live(args, server, transport, bus)
    _stop_on_signals(server)
    if args.factory_reset:  # started: the factory image saved now, a refused run left the state alone
        bus.state_store = store
        bus.save_state()
    print(where, flush=True)  # the first stdout line: the port, which scripts and tests read
    if live is not None and live.url:
        print(live.url, flush=True)
    log.info(
        "serving IDs %s on %s (profile %s%s%s)",
        ",".join(map(str, bus.ids)),
        transport.name,
        args.profile,
        ", paced" if args.pace else "",
        ", echo" if args.echo else "",
    )
    try:
        server.serve_forever()
    finally:
        if live is not None:
            live.close()
        transport.close()
        bus.close()
        if trace is not None:
            trace.close()
        log.info("stopped; %d packets served", server.packets_in)
    return 0


#: Signals that stop a server cleanly (its --link removed, its state saved, "stopped" logged): Ctrl-C, kill, and
#: the terminal or ssh session it runs in closing (SIGHUP: by default it died there, leaving its --link at a
#: freed pty number the next terminal takes).
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


def _stop_on_signals(server: BusServer) -> None:
    for signum in STOP_SIGNALS:
        # A hangup ignored when the process started stays ignored: ``nohup ax12emu serve &`` asks to outlive the
        # session. (SIGINT is taken whatever it was: a script's background job starts with it ignored, and the
        # harness and users stop a server they started with it.)
        if signum == getattr(signal, "SIGHUP", None) and signal.getsignal(signum) is signal.SIG_IGN:
            continue
        signal.signal(signum, lambda signum, frame: server.stop())


def _diagnose(arguments: list[str]) -> int:
    try:
        from firmware_model.diagnose.cli import main as diagnose_main
    except ImportError as exc:
        print(f"ax12emu: diagnose needs scipy and matplotlib: pip install 'ax12emu[diagnose]' ({exc})", file=sys.stderr)
        return 2
    return diagnose_main(_from_the_served_servo(arguments), prog="ax12emu diagnose")


#: Where ``ax12emu diagnose`` writes the served servo's parameters it starts another AX model's export from.
BASE_PARAMS_FILE = "base_params.toml"


def _from_the_served_servo(arguments: list[str]) -> list[str]:
    """The diagnosis's arguments, with ``--params`` added for a Wizard export of another AX model (the AX-18A).

    Why: the workflow's model is the AX-12A's unless given parameters, and an AX-18A's recording diagnosed against
    an AX-12A's motor names the motor.  ``ax12emu`` knows each model's served parameters
    (:func:`~ax12emu.servo.model_factory.datasheet_params`), which the workflow, a layer below, does not read; so
    they are written to ``--out``/:data:`BASE_PARAMS_FILE` and given as ``--params``, and the fitted twin it
    writes then serves as ``serve --servo ax-18a --params``.  Anything this cannot read is left as it is, for the
    workflow to report.
    """
    from ax12emu.servo.model_factory import ax_bus_model, datasheet_params
    from firmware_model.diagnose.cli import parse_args as diagnose_args
    from firmware_model.diagnose.wizard import is_wizard_export, read_wizard_model

    try:
        # Said once, by the workflow itself: a usage error (stderr) and --help (stdout) alike.
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            args = diagnose_args(arguments)
    except SystemExit:  # a bad command line
        return arguments
    if args.params is not None or not is_wizard_export(args.trace):
        return arguments
    try:  # the model line alone: the workflow reads the rows, once
        name, _ = read_wizard_model(args.trace)
    except (ValueError, OSError):
        return arguments
    spec = ax_bus_model(name)
    if spec is None or spec.key == AX12_MODEL:
        return arguments
    path = Path(args.out) / BASE_PARAMS_FILE
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        datasheet_params(spec).to_toml(path, comments=(f"the served {spec.name}'s parameters (ax12emu/protocol/models/"
                                                       f"{spec.key}.toml), where ax12emu diagnose started from",))
    except OSError:
        return arguments
    if not args.quiet:
        print(f"ax12emu diagnose: the export is from an {spec.name}: starting from the served {spec.name}'s parameters "
              f"({path})", file=sys.stderr)
    return [*arguments, "--params", str(path)]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ax12emu`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["diagnose"]:  # its own parser takes every argument, --help included
        return _diagnose(argv[1:])
    args = parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if getattr(args, "verbose", False) else logging.INFO,
        format="%(asctime)s.%(msecs)03d %(name)s %(levelname)s %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
    )
    try:
        if args.command == "serve":
            return _serve(args)
        if args.command in cli_hil.COMMANDS:
            status = cli_hil.COMMANDS[args.command](args)
            sys.stdout.flush()  # here, where a reader that went away is caught, not at the interpreter's exit
            return status
    except (StateFileError, FileExistsError, ValueError) as exc:
        print(f"ax12emu: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader went away (``ax12emu decode big.jsonl | head``): stop quietly. stdout goes to /dev/null so the
        # interpreter's last flush of the lines still buffered cannot fail again (Python's own recipe, "Note on SIGPIPE").
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as exc:
        print(f"ax12emu: {exc}", file=sys.stderr)
        return 1
    return 2
