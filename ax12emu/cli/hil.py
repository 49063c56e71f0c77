"""Command-line parts for testing with the emulator: trace and fault flags, ``decode``, ``conformance``.

Why it exists: keeps :mod:`ax12emu.cli.main` about serving while these grow;
``cli.py`` calls :func:`add_serve_flags`, :func:`add_commands`,
:func:`fault_config` and dispatches through :data:`COMMANDS`.  ``print`` is
allowed here as in ``cli.py``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from ax12emu.cli import models as cli_models
from ax12emu.cli.arg_types import file_name, positive_float, positive_int
from ax12emu.faults.config import FAULT_OPTIONS, FaultConfig
from ax12emu.protocol.control_table import DEFAULT_PROFILE, PROFILES
from ax12emu.protocol.ids import parse_ids

__all__ = ["add_serve_flags", "add_commands", "fault_config", "COMMANDS"]


def _typed(parse: Callable[[str], object]) -> Callable[[str], object]:
    def convert(text: str) -> object:
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = getattr(parse, "__name__", "value").lstrip("_")
    return convert


def _ids(text: str) -> list[int]:
    return parse_ids(text)


def add_serve_flags(serve: argparse.ArgumentParser) -> None:
    """``serve --trace FILE`` and the fault-injection flags (see :mod:`ax12emu.faults.injection`)."""
    # An empty FILE is refused: serve takes a false --trace as none, and would run untraced without a word.
    serve.add_argument("--trace", metavar="FILE", type=file_name, help="record every byte in and out as JSON lines (ax12emu decode FILE)")
    group = serve.add_argument_group(
        "fault injection",
        "what a client sees is listed in the docs of ax12emu.faults.injection; servos are named by their --ids slot",
    )
    parse = {name: _typed(parser) for name, (parser, _) in FAULT_OPTIONS.items()}
    group.add_argument("--drop", type=parse["drop"], default=0.0, metavar="F", help="drop this fraction of status packets (client: timeout)")
    group.add_argument("--corrupt", type=parse["corrupt"], default=0.0, metavar="F", help="send this fraction with a wrong checksum (client: corrupt packet)")
    group.add_argument("--delay", type=parse["delay"], default=0.0, metavar="F", help="send this fraction late (client: timeout)")
    group.add_argument("--delay-s", type=parse["delay_s"], default=0.1, metavar="S", help="how late --delay replies are (default 0.1 s)")
    group.add_argument("--fault-ids", type=parse["fault_ids"], default=(), metavar="LIST", help="apply --drop/--corrupt/--delay to these IDs only")
    group.add_argument("--fault-seed", type=parse["seed"], default=0, metavar="N", help="seed of the random choices (default 0)")
    group.add_argument("--vanish", type=parse["vanish"], action="append", default=[], metavar="ID[:EVERY_S:FOR_S]", help="servo unplugged (always, or FOR_S of every EVERY_S)")
    group.add_argument("--duplicate", type=parse["duplicate"], action="append", default=[], metavar="SLOT:ID", help="servo SLOT takes ID, as if renumbered: it stops answering as SLOT and its replies collide with ID's")
    group.add_argument("--alarm", type=parse["alarm"], action="append", default=[], metavar="ID:NAMES", help="force alarms: overload, overheating, input_voltage")
    group.add_argument("--stall", type=parse["stall"], action="append", default=[], metavar="ID", help="block the servo's shaft")


def fault_config(args: argparse.Namespace) -> FaultConfig:
    """The faults the serve flags ask for."""
    return FaultConfig(
        drop=args.drop,
        corrupt=args.corrupt,
        delay=args.delay,
        delay_s=args.delay_s,
        fault_ids=tuple(args.fault_ids),
        seed=args.fault_seed,
        vanish=tuple(args.vanish),
        duplicate=tuple(args.duplicate),
        alarm=tuple(args.alarm),
        stall=tuple(args.stall),
    )


def add_commands(sub: argparse._SubParsersAction) -> None:
    """The ``decode``, ``conformance`` and ``models`` (:mod:`ax12emu.cli.models`) subcommands."""
    decode = sub.add_parser("decode", help="print a bus trace (or a raw byte capture) as decoded packets")
    decode.add_argument("file", metavar="FILE", help="a JSON-lines trace from serve --trace, or a binary capture")
    decode.add_argument("--raw", action="store_true", help="treat FILE as a raw capture even if it looks like JSON")
    decode.add_argument("--profile", choices=sorted(PROFILES),
                        help=f"the AX-12As' register names by this profile (default: the trace header's, else {DEFAULT_PROFILE})")
    decode.add_argument("--protocol", choices=("auto", "1.0", "2.0", "both"), default="auto",
                        help="frame Protocol 1.0 only, 2.0 only (a wire of X-series servos alone), or both (X-series "
                        "servos beside AX-12s); auto: 2.0 when the trace's header names 2.0 servos only, both when "
                        "the servos named include 2.0 ones or the bytes hold a 2.0 header, else 1.0")
    decode.add_argument("--servo", metavar="SPEC",
                        help="name each ID's registers by its model's table (IDS:MODEL,..., as serve --servo: Protocol 2.0 "
                        "models and 1.0 ones such as mx-28); default: the servos the trace's header names, else the "
                        "AX-12 table of --profile on 1.0 and addresses on 2.0")

    check = sub.add_parser("conformance", help="run the Protocol 1.0 (or 2.0) checks against any port (emulator or servo)")
    check.add_argument("port", metavar="PORT", help="device path or pyserial URL (socket://HOST:PORT, ax12emu://...)")
    check.add_argument("--ids", type=_typed(_ids), default=[1], metavar="LIST", help="IDs on the bus to check (default 1)")
    check.add_argument("--baud", type=positive_int, default=None,
                       help="host bit rate (default 1000000, the AX series' factory rate: an MX at its factory Baud Rate 34 needs "
                       "57600; with --protocol 2.0, 57600: the X series' factory Baud Rate 1)")
    check.add_argument("--timeout-ms", type=positive_float, default=50.0, metavar="MS", help="reply timeout (default 50)")
    check.add_argument("--silence-ms", type=positive_float, default=None, metavar="MS",
                       help="how long a packet that must get no reply is listened to (default: the reply timeout, safe "
                       "behind a USB adapter's 16 ms latency timer; a bus that answers at once, as the emulator does, "
                       "can take less; a reply that comes later, before the next packet, still fails the check)")
    check.add_argument("--destructive", action="store_true", help="also change ID, baud and RESET (all restored afterwards)")
    check.add_argument("--motion", action="store_true",
                       help="also run the checks that turn the shaft (Protocol 2.0: velocity and current modes, the two "
                       "profiles; up to about a turn each way at a third of the no-load speed, torque on, then off and "
                       "every register put back). A flag of its own, apart from --destructive: those put the bus at risk "
                       "(ID, baud), these what is on the horn; run them only with the horn free to turn")
    check.add_argument("--profile", choices=sorted(PROFILES), default=DEFAULT_PROFILE, help="the AX-12A's table edition whose defaults are expected "
                       "(other models: their model file's)")
    check.add_argument("--only", action="append", metavar="CHECK", help="run only this check (repeatable)")
    check.add_argument("--protocol", choices=("1.0", "2.0"), default="1.0",
                       help="1.0 (AX and MX series; the table comes from the model number each servo holds) or 2.0 (X series; "
                       "the table comes from the model number each servo pings)")

    cli_models.add_command(sub)


#: The host rate a suite starts at unless told: the servos' factory Baud Rate, 1 Mbps on the AX-12
#: (Protocol 1.0) and 57,600 bps on the X series (e-manual, e.g. XL430-W250 "Baud Rate(8)": initial 1, 57,600).
FACTORY_BAUD_BPS = {"1.0": 1_000_000, "2.0": 57_600}


def _until_unreadable(chunks):
    """``chunks`` up to a line that cannot be read (a killed server's torn last line): the protocol is chosen from
    what comes before it, so the decoding pass prints every line up to it and then stops with its error, as it
    does with ``--protocol`` given."""
    try:
        yield from chunks
    except ValueError:
        return


def _decode(args: argparse.Namespace) -> int:
    from ax12emu.tracing.decoder import choose_protocol, format_decoded, iter_decode
    from ax12emu.tracing.trace import read_capture, read_raw, trace_header

    read = read_raw if args.raw else read_capture
    header = {} if args.raw else trace_header(args.file)
    servos = args.servo if args.servo is not None else header.get("servos")
    profile = args.profile if args.profile is not None else header.get("profile", DEFAULT_PROFILE)
    if not isinstance(profile, str) or profile not in PROFILES:  # the header is a file's word: checked as the flag is
        raise ValueError(f"{args.file}: the header's profile {profile!r} is none of {', '.join(sorted(PROFILES))}")
    if servos is not None and not isinstance(servos, str):
        raise ValueError(f"{args.file}: the header's servos must be a text such as \"1-5:xm430-w350\", got {servos!r}")
    if args.servo is not None and ":" not in args.servo:  # serve's bare MODEL takes its IDs from --ids; decode has none
        raise ValueError(f"--servo {args.servo}: decode needs IDS:MODEL[,IDS:MODEL...] (e.g. 1-5:xm430-w350)")
    # auto: a first reading of the file only chooses (it needs every byte), so the second prints each line as it is
    # decoded, in memory flat in the trace's length
    protocol = choose_protocol(_until_unreadable(read(args.file)), servos) if args.protocol == "auto" else args.protocol
    echo = header.get("echo")  # serve records whether the adapter echoed: without, no servo bytes are an echo
    shown = 0
    for item in iter_decode(read(args.file), profile=profile, protocol=protocol, servos=servos,
                            echo=echo if isinstance(echo, bool) else None):
        print(format_decoded(item))
        shown += 1
    if not shown:  # a server stopped before any packet, or an empty capture: say so rather than print nothing
        print(f"{args.file}: no bytes to decode (a trace of a session with no packets, or an empty capture)", file=sys.stderr)
    return 0


def _conformance(args: argparse.Namespace) -> int:
    from ax12emu import conformance

    report = conformance.run(
        args.port,
        args.ids,
        baud=args.baud if args.baud is not None else FACTORY_BAUD_BPS[args.protocol],
        timeout_s=args.timeout_ms / 1e3,
        silence_s=None if args.silence_ms is None else args.silence_ms / 1e3,
        destructive=args.destructive,
        profile=args.profile,
        only=args.only,
        protocol=args.protocol,
        motion=args.motion,
    )
    print(f"{args.port}, IDs {','.join(map(str, args.ids))}, Protocol {args.protocol}")
    print(report.table())
    sys.stdout.flush()
    return 0 if report.passed else 1


#: Subcommand name -> runner.
COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "decode": _decode, "conformance": _conformance, "models": cli_models.run,
}
