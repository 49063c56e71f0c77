# SPDX-License-Identifier: MIT
#
# pyserial URL handler: a virtual AX-12 bus in this process, no pty, no socket.
#
# URL format: ax12emu://[NAME][?OPTION=VALUE[&...]]
#
#   ax12emu://?ids=1,2            a private bus of its own, closed with the port
#   ax12emu://NAME                the bus a VirtualBus(transport="inprocess", name=NAME) serves
#
# Options of a private bus:
#   ids=LIST          servo IDs, e.g. 1,2,5 or 1-18 (default 1)
#   profile=NAME      control-table profile (ax12a, ax12-2006)
#   virtual_time=0|1  physics in virtual time (it then stands still)
#   goal_torque=on|unchanged  writing Goal Position turns the torque on (default) or not
#   eeprom_busy_ms=MS  a servo ignores packets MS per byte after writing its EEPROM (default 6, 0 with
#                     virtual_time=1, where time stands still and a busy servo would never answer again)
#   trace=FILE        record every byte as JSON lines (ax12emu decode FILE)
#   params=FILE       servo parameters as TOML, effects included (e.g. firmware_model.diagnose's params.toml)
#   drop, corrupt, delay, delay_s, fault_ids, seed, vanish, duplicate, alarm, stall:
#                     fault injection, as the serve flags (see ax12emu.faults.injection)
#   servo=SPEC        other models instead of AX-12As, as `ax12emu serve --servo` takes them:
#                     MODEL for every ID of ids= (default 1), or IDS:MODEL,... alone
#                     (e.g. servo=xl430-w250&ids=1-6, servo=mx-28&ids=1-4, servo=1-5:xm430-w350,6:xl330-m077);
#                     Protocol 1.0 models among X-series ones share the wire (servo=1-2:ax-12a,3:mx-64,4-6:xl430-w250)
#   baud=BPS          with servo=: every servo starts at this bit rate (default: each model's factory
#                     rate, 57600 on the X and MX series); the port must be opened at the same rate
#                     With servo=, the same faults apply; alarm and stall act through the X-series
#                     firmware (ax12emu.faults.injection.Faults2, Faults1X on MX servos).
# Options of any URL:
#   logging=debug|info|warning|error   per-handler logger "ax12emu.harness.urlhandler"
#
# Reads block up to the port's timeout like a real port and return the
# bytes that have arrived; a status packet arrives Return Delay Time after
# its instruction was written.  The port's baud rate is the host's line rate:
# a servo set to another baud does not hear it.
"""pyserial ``Serial`` class for ``ax12emu://`` URLs (registered on ``import ax12emu``)."""

from __future__ import annotations

import logging
import numbers
import urllib.parse

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, to_bytes

from ax12emu.bus import Bus
from ax12emu.bus.bus1x import Bus1X
from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock, WallClock
from ax12emu.bus.mixed import MixedBus
from ax12emu.bus.wire import servo_family
from ax12emu.faults.config import FAULT_OPTIONS, FaultConfig
from ax12emu.harness.inprocess import InProcessLink, LinkBusy, LinkClosed, LinkDetached, lookup
from ax12emu.harness.servos2 import build_wire, servo_list, servo_models
from ax12emu.protocol.ids import parse_ids
from ax12emu.servo.model_factory import ModelChoice, build_model
from ax12emu.servo.virtual_servo import EEPROM_BUSY_MAX_S, ServoOptions
from ax12emu.tracing.trace import TraceWriter

__all__ = ["Serial", "UrlError", "EXPECTED"]

EXPECTED = (
    'expected "ax12emu://[NAME][?ids=LIST&profile=NAME&virtual_time=0|1&goal_torque=on|unchanged'
    '&eeprom_busy_ms=MS&trace=FILE&params=FILE&seed=N&drop=F&...'
    '&servo=MODEL|IDS:MODEL,...&baud=BPS'
    '&logging={debug|info|warning|error}]"'
)
LOGGER_LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR}
#: Options of a private bus besides the fault ones.
BUS_OPTIONS = ("ids", "profile", "virtual_time", "goal_torque", "eeprom_busy_ms", "trace", "params", "servo", "baud")
#: Options a bus of other models (servo=) takes; goal_torque, eeprom_busy_ms and params shape its AX servos (AX-12A,
#: AX-18A), and profile the AX-12A bus alone.
SERVO_OPTIONS = ("ids", "virtual_time", "trace", "servo", "baud", "goal_torque", "eeprom_busy_ms", "params",
                 "drop", "corrupt", "delay", "delay_s", "fault_ids", "seed", "vanish", "duplicate", "alarm", "stall")


def _ax_options(options: dict[str, list[str]], busy_default_s: float, profile: str = "ax12a") -> ServoOptions:
    """The AX bus's options from the URL's goal_torque and eeprom_busy_ms (taken out of ``options``; the pause
    ``busy_default_s`` per byte where eeprom_busy_ms is not given); ValueError for a bad value."""
    goal_torque = options.pop("goal_torque", ["on"])[-1]
    if goal_torque not in ("on", "unchanged"):
        raise ValueError(f"goal_torque must be on or unchanged, got {goal_torque!r}")
    busy_s = busy_default_s
    if "eeprom_busy_ms" in options:
        busy_s = _eeprom_busy_ms(options.pop("eeprom_busy_ms")[-1]) * 1e-3
    return ServoOptions(profile=profile, goal_position_enables_torque=goal_torque == "on", eeprom_busy_s_per_byte=busy_s)


def _eeprom_busy_ms(text: str) -> float:
    """The URL's eeprom_busy_ms in milliseconds; ValueError naming the option as written, in its unit (ServoOptions'
    own check names its field in seconds, which the URL never shows)."""
    try:
        busy_ms = float(text)
    except ValueError:
        raise ValueError(f"eeprom_busy_ms: must be a number of milliseconds, got {text!r}") from None
    if not 0.0 <= busy_ms <= EEPROM_BUSY_MAX_S * 1e3:  # also refuses NaN
        raise ValueError(f"eeprom_busy_ms: must lie in 0..{EEPROM_BUSY_MAX_S * 1e3:g} ms, got {text}")
    return busy_ms


def _trace_writer(path: str | None, **header: str) -> TraceWriter | None:
    """The ``trace=`` file's writer (None without one); a path that cannot be written is a :class:`UrlError`."""
    if not path:
        return None
    try:
        writer = TraceWriter(path, **header)
        writer.note(echo=False)  # the in-process link echoes nothing: the decoder never takes a reply for an echo
        return writer
    except OSError as exc:
        raise UrlError(f"{EXPECTED}: trace={path}: {exc.strerror or exc}") from None


def heard_at_8n1(bytesize: int, parity: str, break_held: bool) -> bool:
    """Whether a servo's UART (8 data bits, no parity, 1 stop bit) takes a host's bytes in this format.

    Extra stop bits are idle line, and a mark parity bit (always 1) reads as the stop bit: heard.  Fewer data
    bits put the host's stop bit among the servo's data bits and the next start bit on its stop bit; an even,
    odd or space parity bit is 0 on the stop bit for many bytes; a held break is a line held low: framing
    errors, so no packet (whose every byte must arrive whole) reaches the servo.
    """
    return bytesize == 8 and parity in ("N", "M") and not break_held


class UrlError(SerialException, ValueError):
    """A malformed ax12emu:// URL: both a SerialException (pyserial's habit) and a ValueError."""


class Serial(SerialBase):
    """A serial port whose other end is a virtual bus in this process."""

    def __init__(self, *args, **kwargs) -> None:
        self._link: InProcessLink | None = None
        #: This port's session on the link (``InProcessLink.attach``): a read or write racing close() ends with it.
        self._session = 0
        self._private: tuple[Bus | Bus1X | Bus2 | MixedBus, TraceWriter | None] | None = None
        self.logger: logging.Logger | None = None
        super().__init__(*args, **kwargs)

    # -- opening and closing -------------------------------------------------------------
    def open(self) -> None:
        """Attach to the bus the URL names (or build a private one)."""
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        link = self.from_url(self.portstr)
        try:
            self._reconfigure_port()  # before claiming the bus: a refused setting leaves it free, as pyserial's ports do
            if link.closed:
                raise LinkClosed("the in-process bus was closed")
            self._session = link.attach()
        except (LinkBusy, LinkClosed) as exc:
            self._close_private()
            raise SerialException(f"{self.portstr}: {exc}") from None
        except BaseException:
            self._close_private()
            raise
        self._link = link
        self.is_open = True

    def close(self) -> None:
        """Detach; a private bus is closed with its port."""
        if self.is_open and self._link is not None:
            self._link.detach()
        self._link = None
        self._close_private()
        self.is_open = False

    def _close_private(self) -> None:
        if self._private is not None:
            bus, trace = self._private
            self._private = None
            bus.close()
            if trace is not None:
                trace.close()

    def from_url(self, url: str) -> InProcessLink:
        """Parse the URL; unknown or bad options raise :class:`UrlError` quoting the expected form."""
        parts = urllib.parse.urlsplit(url)
        if parts.scheme.lower() != "ax12emu":
            raise UrlError(f"{EXPECTED}: not starting with ax12emu:// ({url!r})")
        try:
            options = urllib.parse.parse_qs(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
        except ValueError as exc:
            raise UrlError(f"{EXPECTED}: {exc}") from None
        # Which one counts would be a guess (ids=1&ids=2 served ID 2 alone); a fault that names one servo repeats as
        # its serve flag does (stall=1&stall=2), one per servo.
        repeated = sorted(key for key, values in options.items()
                          if len(values) > 1 and not (key in FAULT_OPTIONS and FAULT_OPTIONS[key][1]))
        if repeated:
            raise UrlError(f"{EXPECTED}: {', '.join(repeated)} given more than once")
        blank = sorted(key for key, values in options.items() if not values[-1].strip())
        if blank:  # params= served the default model and trace= recorded nothing, without a word
            raise UrlError(f"{EXPECTED}: {', '.join(f'{key}=' for key in blank)} given no value")
        level = options.pop("logging", None)
        if level is not None:
            if level[-1] not in LOGGER_LEVELS:
                raise UrlError(f"{EXPECTED}: unknown logging level {level[-1]!r}")
            self.logger = logging.getLogger("ax12emu.harness.urlhandler")
            self.logger.setLevel(LOGGER_LEVELS[level[-1]])
        name = (parts.netloc + parts.path).strip("/")
        if name:
            if options:
                raise UrlError(f"{EXPECTED}: a named bus takes no options, got {sorted(options)}")
            try:
                return lookup(name)
            except KeyError as exc:
                raise SerialException(f"{url}: {exc.args[0]}") from None
        unknown = sorted(set(options) - set(BUS_OPTIONS) - set(FAULT_OPTIONS))
        if unknown:
            raise UrlError(f"{EXPECTED}: unknown option(s) {', '.join(unknown)}")
        if "servo" in options:
            return self._servo_bus(options)
        if "baud" in options:
            raise UrlError(f"{EXPECTED}: baud= applies with servo= (the AX-12A bus starts at 1000000)")
        try:
            ids = parse_ids(options.pop("ids", ["1"])[-1])
            profile = options.pop("profile", ["ax12a"])[-1]
            virtual = options.pop("virtual_time", ["0"])[-1]
            if virtual not in ("0", "1"):
                raise ValueError(f"virtual_time must be 0 or 1, got {virtual!r}")
            # Without eeprom_busy_ms a virtual-time bus answers at once (its clock does not run alone).
            servo_options = _ax_options(options, 0.0 if virtual == "1" else ServoOptions().eeprom_busy_s_per_byte, profile)
            trace_path = options.pop("trace", [None])[-1]
            params_path = options.pop("params", [None])[-1]
            model = build_model(ModelChoice(params_path=params_path, profile=profile), len(ids)) if params_path else None
            faults = FaultConfig.from_options(options)
            bus = Bus(ids, model=model, options=servo_options, clock=VirtualClock() if virtual == "1" else WallClock())
            if faults.active:
                faults.install(bus)
        except ValueError as exc:
            raise UrlError(f"{EXPECTED}: {exc}") from None
        trace = _trace_writer(trace_path, profile=profile)
        self._private = (bus, trace)
        if self.logger:
            self.logger.info("private bus with IDs %s", ids)
        return InProcessLink(bus, trace=trace)

    def _servo_bus(self, options: dict[str, list[str]]) -> InProcessLink:
        """A private bus of the models ``servo=`` names; options of the AX-12A bus are refused by name."""
        refused = sorted(set(options) - set(SERVO_OPTIONS))
        if refused:
            raise UrlError(f"{EXPECTED}: {', '.join(refused)} not available with servo= (the AX-12A bus alone takes it)")
        try:
            spec = options["servo"][-1]
            ids = parse_ids(options["ids"][-1]) if "ids" in options else None
            virtual = options.get("virtual_time", ["0"])[-1]
            if virtual not in ("0", "1"):
                raise ValueError(f"virtual_time must be 0 or 1, got {virtual!r}")
            baud_text = options.get("baud", [None])[-1]
            try:
                baud_bps = None if baud_text is None else float(baud_text)
            except ValueError:
                raise ValueError(f"baud must be a bit rate, got {baud_text!r}") from None
            faults = FaultConfig.from_options({name: texts for name, texts in options.items() if name in FAULT_OPTIONS})
            # The AX servos' EEPROM pause: none in virtual time, where time stands still and a busy servo would never
            # answer again (as on the AX-12A bus without servo=); else the one they have without the options.
            busy_s = 0.0 if virtual == "1" else ServoOptions().eeprom_busy_s_per_byte
            names_ax = any(servo_family(key) == "AX" for _, key in servo_models(spec, ids, mixed=True))
            given = bool({"goal_torque", "eeprom_busy_ms"} & set(options))  # refused by build_wire where no AX servo is
            options1 = _ax_options(dict(options), busy_s) if given or (names_ax and virtual == "1") else None
            params_path = options.get("params", [None])[-1]
            bus = build_wire(spec, ids, clock=VirtualClock() if virtual == "1" else WallClock(), baud_bps=baud_bps,
                             choice1=None if params_path is None else ModelChoice(params_path=params_path), options1=options1)
            if faults.active:
                faults.install(bus)
        except ValueError as exc:
            raise UrlError(f"{EXPECTED}: {exc}") from None
        trace_path = options.get("trace", [None])[-1]
        servos = servo_list(bus)
        trace = _trace_writer(trace_path, servos=servos)
        self._private = (bus, trace)
        if self.logger:
            self.logger.info("private bus of %s (%s)", servos, type(bus).__name__)
        return InProcessLink(bus, trace=trace)

    def _reconfigure_port(self) -> None:
        if not isinstance(self._baudrate, numbers.Integral) or not 0 < self._baudrate < 2**32:
            raise ValueError(f"invalid baudrate: {self._baudrate!r}")

    # -- data ----------------------------------------------------------------------------
    @property
    def in_waiting(self) -> int:
        """Bytes that can be read without waiting."""
        link = self._link  # once: close() in another thread sets it to None
        if not self.is_open or link is None:
            raise PortNotOpenError()
        return link.in_waiting()

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, waiting up to the timeout (None: until all arrive, or :meth:`cancel_read`); b"" once
        the port is closed meanwhile (from another thread)."""
        link, session = self._link, self._session
        if not self.is_open or link is None:
            raise PortNotOpenError()
        try:
            data = link.read(size, self._timeout, session)
        except LinkClosed as exc:
            raise SerialException(f"{self.portstr}: {exc}") from None
        if self.logger:
            self.logger.debug("read %s", data.hex(" "))
        return data

    def write(self, data) -> int:
        """Send bytes to the servos; they act on whole packets at once.

        Takes what pyserial's own ports take (``to_bytes``): bytes-likes and
        sequences of ints, which dynamixel-sdk writes.
        """
        link, session = self._link, self._session
        if not self.is_open or link is None:
            raise PortNotOpenError()
        payload = bytes(to_bytes(data))
        if self.logger:
            self.logger.debug("write %s", payload.hex(" "))
        if not heard_at_8n1(self._bytesize, self._parity, bool(self._break_state)):
            return len(payload)  # sent, into framing errors
        try:
            return link.write(payload, float(self._baudrate), session)
        except LinkClosed as exc:
            raise SerialException(f"{self.portstr}: {exc}") from None
        except LinkDetached:  # closed by another thread since the check above
            raise PortNotOpenError() from None

    def cancel_read(self) -> None:
        """Make a read blocked in another thread return at once with what has arrived (pyserial's ``cancel_read``)."""
        link = self._link
        if link is not None:
            link.cancel_read()

    def cancel_write(self) -> None:
        """Writes complete at once: nothing to cancel."""

    def flush(self) -> None:
        """Writes complete at once: nothing to wait for."""
        if not self.is_open:
            raise PortNotOpenError()

    def reset_input_buffer(self) -> None:
        """Drop received bytes."""
        link = self._link
        if not self.is_open or link is None:
            raise PortNotOpenError()
        link.clear_input()

    def reset_output_buffer(self) -> None:
        """Nothing is ever waiting to be sent."""
        if not self.is_open:
            raise PortNotOpenError()

    @property
    def out_waiting(self) -> int:
        """Writes complete at once."""
        if not self.is_open:
            raise PortNotOpenError()
        return 0

    # -- modem lines: there are none; answer like a plain 3-wire adapter ----------------
    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True
