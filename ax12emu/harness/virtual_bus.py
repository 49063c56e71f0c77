"""Start and stop a served bus from Python, and reach into its servos.

Why it exists: a user's test wants servos in a few lines and must be able
to do to them what the bench cannot: set a temperature, block a shaft, push
on it, drop replies, or step time exactly.  :class:`VirtualBus` owns a
:class:`~ax12emu.bus.bus.Bus`, a transport and (for a pty or TCP) the serving
thread, and tears all of it down on ``close``, also when the ``with`` body
raises.  Everything that touches the bus runs on the serving thread (or
under the in-process link's lock), so a test never races a packet::

    with ax12emu.VirtualBus(ids=[1, 2]) as bus:
        port = PortHandler(bus.port)          # any client: dynamixel-sdk, pyserial, ...
        bus.set_temperature(1, 80)            # -> Overheating bit in every status packet
        bus.faults.set_reply_faults(drop=0.5) # -> half the replies time out

Servos are addressed by their present ID in the state methods, and by their
*slot* (the ID they were launched with) in ``bus.faults`` (see
:mod:`ax12emu.faults.injection`).

``servo=`` serves the models the text names instead, read as ``ax12emu serve --servo`` reads it:
the X series on Protocol 2.0 (``VirtualBus([1, 2], servo="xl430-w250")`` or
``VirtualBus(servo="1-5:xm430-w350,6:xl330-m077")``, ``options=Servo2Options(...)`` for the
behaviours the e-manual leaves open), the MX series on Protocol 1.0 (``servo="mx-28"``), and
AX-12As, AX-18As and MX servos beside them on one wire (``servo="1-2:ax-12a,3:mx-64,4-6:xl430-w250"``);
``params=``, ``model="kinematic"`` and ``options=ServoOptions(...)`` shape its AX-12As and AX-18As, as
``--params`` and the AX bus's flags do on the command line.  Which bus serves them is decided once
(:func:`~.servos2.build_wire`); every method here then finds the servo and the bus holding it
through the buses' own interface (``servo``, ``holder``), and tells a servo with a firmware model of
its own (X, MX) from an AX-12 by that model, never by its kind.  IDs are per protocol, so an ID both protocols have needs ``protocol=1.0`` or ``2.0`` in
the state methods and in ``bus.faults`` (:class:`~ax12emu.faults.injection.MixedFaults`; a
ValueError says so).  Each servo has its model's table, and the register methods take that
table's names (``bus.read(1, "present_position")``).  What is not offered here with ``servo=``
(a set angle on a firmware's shaft) is refused with the reason; ``web=`` shows any wire, as
``ax12emu serve --servo ... --web`` does; the faults work
(:class:`~ax12emu.faults.injection.Faults2`, :class:`~ax12emu.faults.injection.Faults1X`: the
wire's, and alarm, stall, hold and pinned temperature or voltage acted out by each servo's firmware).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import numbers
import operator
import os
import threading
import weakref
from collections.abc import Callable, Iterable
from typing import Any

from ax12emu.bus.bus import Bus
from ax12emu.bus.bus1x import Bus1X
from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.clock import VirtualClock, WallClock
from ax12emu.bus.mixed import MixedBus, model_name
from ax12emu.bus.wire import start_at_baud
from ax12emu.faults.config import FaultConfig
from ax12emu.faults.injection import Faults
from ax12emu.live.controls import ServedControls
from ax12emu.servo.classic import GOAL_REGISTERS as CLASSIC_GOAL_REGISTERS
from ax12emu.servo.model_factory import ModelChoice, build_model
from ax12emu.servo.servo2 import GOAL_REGISTERS, Servo2Options
from ax12emu.servo.virtual_servo import ServoOptions
from ax12emu.tracing.trace import TraceWriter
from firmware_model.interface import AngleSettable, ServoModel
from firmware_model.params import ServoParams

from .inprocess import InProcessLink, NameTaken, check_name, is_registered, register, unregister
from .servos2 import build_wire, servo_list

__all__ = ["VirtualBus", "TRANSPORTS"]

log = logging.getLogger(__name__)

#: How long a call waits for the serving thread (s): it runs calls between packets, within about a millisecond.
_CALL_TIMEOUT_S = 5.0

#: Where a VirtualBus can put its servos.
TRANSPORTS = ("pty", "tcp", "inprocess")
#: Degrees of travel per radian, and the AX-12's 300-degree range over positions 0..1023.
_DEG_PER_RAD = 180.0 / math.pi
#: Registers whose write starts a new move in a firmware of its own: the X series' Goal registers and the
#: classic tables' (MX, XL-320); a table has only its own family's names, so one set serves every model.
_GOAL_REGISTERS = GOAL_REGISTERS | CLASSIC_GOAL_REGISTERS
#: Any bus the harness builds.
AnyBus = Bus | Bus1X | Bus2 | MixedBus

_instances = 0
_instances_lock = threading.Lock()


def _next_name() -> str:
    """A name no in-process bus holds now ("bus1", "bus2", ...: a user may have named one so)."""
    global _instances
    with _instances_lock:
        while True:
            _instances += 1
            name = f"bus{_instances}"
            if not is_registered(name):
                return name


def _check_types(*, options: Any, model: Any, faults: Any, servo: Any, baud_bps: Any) -> None:
    """A TypeError naming the argument whose type is wrong (they failed deep inside: ``model=5`` as "'int' object has
    no attribute 'n'")."""
    if options is not None and not isinstance(options, (ServoOptions, Servo2Options)):
        raise TypeError(f"options must be a ServoOptions (AX-12A bus) or Servo2Options (servo=), got {type(options).__name__}")
    if (servo is None and model is not None and not isinstance(model, str)  # (servo= refuses any model object)
            and not callable(getattr(model, "advance", None))):
        raise TypeError(f"model must be 'physical', 'kinematic' or a firmware_model.ServoModel, got {type(model).__name__}")
    if faults is not None and not isinstance(faults, FaultConfig):
        raise TypeError(f"faults must be an ax12emu.faults.FaultConfig, got {type(faults).__name__}")
    if servo is not None and not isinstance(servo, str):
        raise TypeError(f"servo must be a text such as '1-2:xl430-w250', got {type(servo).__name__}")
    if baud_bps is not None and (isinstance(baud_bps, bool) or not isinstance(baud_bps, numbers.Real)):
        raise TypeError(f"baud_bps must be a bit rate, got {type(baud_bps).__name__}")
    if baud_bps is not None and not math.isfinite(baud_bps):  # NaN matched no rate and set the first Baud Rate value
        raise ValueError(f"baud_bps must be a finite bit rate, got {baud_bps!r}")


def _fault_seed(seed: int | None, faults: FaultConfig | None) -> int:
    """The one seed of the bus's faults, those ``faults=`` starts with and those added later through ``bus.faults``:
    ``seed=``, or the FaultConfig's own where ``seed=`` is left out; a FaultConfig at its default seed (0) takes
    ``seed=``.  Both given and different is a ValueError: either choice would silently drop the other."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, numbers.Integral)):
        raise TypeError(f"seed must be an integer, got {type(seed).__name__}")
    own = 0 if faults is None else faults.seed
    if seed is None:
        return own
    if own not in (0, seed):
        raise ValueError(f"seed={seed} and faults=FaultConfig(seed={own}) give two seeds for one bus's faults; give one")
    return int(seed)


def _web_address(web: str | tuple[str, int] | bool | None) -> tuple[str, int] | None:
    if web is None or web is False:
        return None
    if web is True:
        return ("127.0.0.1", 0)
    if isinstance(web, str):
        from ax12emu.serve.transports.tcp import parse_host_port

        return parse_host_port(web)
    host, port = web
    return (str(host), int(port))


def _check_local(what: str, address: tuple[str, int] | None, allow_remote: bool) -> None:
    """ValueError for an address beyond loopback without ``allow_remote=True``: as ``ax12emu serve`` asks for
    ``--allow-remote``, a bus other machines can reach (servos anyone may drive, a page anyone may use) is asked for
    by name, never the side effect of an address such as 0.0.0.0."""
    from ax12emu.serve.transports.tcp import is_loopback

    if address is not None and not allow_remote and not is_loopback(address[0]):
        raise ValueError(f"{what}: {address[0]} binds beyond loopback, where other machines reach it; "
                         "pass allow_remote=True to mean that")


def _find(bus: AnyBus, servo_id: int, protocol: float | None) -> tuple[Any, Any]:
    """(the bus holding it, the servo) answering to ``servo_id`` (on ``protocol``, which a bus of one protocol checks).

    The holder is the bus whose faults and model are the servo's (``holder``: an AX-12A beside MX
    servos is held by the AX-12 bus inside their bus).
    """
    servo = bus.servo(servo_id, protocol)
    return bus.holder(servo), servo


def _firmware(servo: Any) -> Any:
    """The firmware model behind a servo that has one of its own (the X and MX series), else None (an AX-12's
    shaft is its bus's model's)."""
    return getattr(getattr(servo, "plant", None), "firmware", None)


def _as_a_request_finds_it(holder: Any) -> None:
    """Bring ``holder``'s servos to where a client's request would find them now (its ``advance``: a write's
    consequence shown, as the firmware's loop runs before the next packet, and the clock's time reached).

    Why: read straight from the table, a register lagged a write until the next packet or step (Torque Enable 0
    beside the old Present PWM and Current; Present Position without a new Homing Offset), where a client's own
    read, a moment later, saw the consequence."""
    if isinstance(holder, Bus):  # the AX-12 bus takes a write's step where a request comes (its advance only what is due)
        holder.catch_up_for_request()
    else:
        holder.advance()


def _servo_with(bus: AnyBus, servo_id: int, name: str, protocol: float | None = None) -> tuple[Any, Any]:
    """:func:`_find`; KeyError naming the register its model's table lacks."""
    holder, servo = _find(bus, servo_id, protocol)
    if name not in servo.table.layout.by_name:
        raise KeyError(f"{model_name(servo)} has no register {name!r} (ID {servo_id}); table(ID) lists its registers")
    return holder, servo


def _serve(server: Any, name: str, dropped: "_Dropped") -> None:
    """The serving thread: it holds what it serves with (the server, the bus's name), never the VirtualBus, so a
    bus its user dropped unclosed is still collected; it then releases that bus (:func:`_release_dropped`)."""
    try:
        server.serve_forever()
    except Exception:  # pragma: no cover - reported, and close() still cleans up
        log.exception("the serving thread of %s stopped", name)
    if dropped.held is not None:
        _release(dropped.held)


@dataclasses.dataclass(frozen=True)
class _Held:
    """What a started VirtualBus holds open, none of which refers back to it: so a collected bus can still be
    released (its finalizer may not hold the bus), and close() releases it through the same code."""

    name: str
    bus: Any
    live: Any = None
    server: Any = None
    thread: threading.Thread | None = None
    link: InProcessLink | None = None
    transport: Any = None
    trace: TraceWriter | None = None


class _Dropped:
    """What a bus collected unclosed held, once its finalizer has run (None before): for a thread of its own to
    release (:func:`_release_dropped`)."""

    held: _Held | None = None


def _release(held: _Held) -> None:
    """Stop serving, join the thread, close the port and the trace."""
    if held.live is not None:  # first: it reads the bus through the serving thread
        held.live.close()
    if held.server is not None:
        held.server.stop()
    if held.thread is not None and held.thread is not threading.current_thread():
        held.thread.join(5.0)
        if held.thread.is_alive():  # pragma: no cover
            log.error("serving thread of %s did not stop", held.name)
    if held.link is not None:
        unregister(held.name, held.link)
        held.link.close()  # a port still open on it fails from now on, as an unplugged adapter's
    if held.transport is not None:
        held.transport.close()
    held.bus.close()
    if held.trace is not None:
        held.trace.close()


def _release_dropped(held: _Held, dropped: _Dropped) -> None:
    """A started bus collected unclosed: said, and its release handed to a thread it has.

    A collection runs wherever an allocation falls, on any thread and inside any lock that thread holds (the
    name registry's, a link's, threading's own), so nothing here takes a lock but logging's (reentrant) or starts
    a thread: the serving thread, told to stop, releases the rest as it ends; an in-process bus's live view does
    so at its next sample (:func:`_weak_call`).  An in-process bus without one has no thread to do it: its link is
    marked closed (a plain store, no lock), so a port still open on it fails at its next read or write as on
    every other transport; its name, in a registry of weak references, goes with the link, and a ``trace=``
    file is closed when the collector reaches it.
    """
    log.warning("VirtualBus %s was never closed; closing it", held.name)
    dropped.held = held
    if held.server is not None:
        held.server.stop()
    if held.link is not None:
        held.link.closed = True


def _weak_call(owner: "weakref.ReferenceType[VirtualBus]", dropped: _Dropped) -> Callable[[Callable[[Any], Any]], Any]:
    """``owner().call`` for an in-process bus's live view, which must not keep the bus alive: once the bus is
    collected unclosed, the first sample after starts the release on a thread of its own (the release joins the
    sampling thread) and fails, as a sample of a closed bus does."""

    def call(fn: Callable[[Any], Any]) -> Any:
        bus = owner()
        if bus is not None:
            return bus.call(fn)
        held, dropped.held = dropped.held, None
        if held is not None:
            threading.Thread(target=_release, args=(held,), name=f"ax12emu-{held.name}-release", daemon=True).start()
        raise RuntimeError("the VirtualBus of this live view was collected unclosed")

    return call


class _FaultsOnBus:
    """``bus.faults``: every Faults method, run where the bus is served."""

    def __init__(self, owner: "VirtualBus") -> None:
        self._owner = owner

    def __getattr__(self, name: str) -> Any:
        if not callable(getattr(Faults, name, None)):
            return self._owner.call(lambda bus: getattr(self._owner._faults(bus), name))

        def method(*args: Any, **kwargs: Any) -> Any:
            return self._owner.call(lambda bus: getattr(self._owner._faults(bus), name)(*args, **kwargs))

        return method


class VirtualBus:
    """A running bus of virtual AX-12s with a port any client can open (``port``).

    ``virtual_time=True`` without ``options=``: a servo takes no busy time after an EEPROM write (6 ms a byte
    on the wall clock), as ``ax12emu://?virtual_time=1``: simulated time stands still until :meth:`step`, so a
    busy servo would be deaf until then; ``options=ServoOptions(eeprom_busy_s_per_byte=...)`` sets it.
    ``allow_remote=True``: ``tcp_address`` and ``web`` may bind beyond loopback (as ``serve --allow-remote``).
    ``name``: the in-process port is ``ax12emu://NAME``, so a name holding "/", "?", "#" or brackets, or a
    blank one, is refused; without one a free name ``busN`` is taken.
    ``seed``: the one seed of the faults, those of ``faults=`` and those added through :attr:`faults`; left out,
    the FaultConfig's own (a FaultConfig at its default seed 0 takes ``seed=``; two different seeds are a
    ValueError).  ``baud_bps``: every servo starts at that rate, its Baud Rate set to the value its model gives
    for it, on the AX-12A bus as with ``servo=``.

    Its lifetime: close it (:meth:`close`, or a ``with`` block).  On every transport a started bus no longer
    referenced is released when Python collects it, with a warning that it was never closed: its serving thread
    and live view stop and its port goes (a port still open on it fails at its next read or write), so keep
    the bus itself, not only its ``port``, for as long as clients use it.  Neither its serving thread nor its
    live view holds it, so a forgotten bus keeps no thread or descriptor open past a collection.
    """

    def __init__(
        self,
        ids: Iterable[int] | None = None,
        *,
        transport: str = "pty",
        virtual_time: bool = False,
        time_scale: float = 1.0,
        options: ServoOptions | Servo2Options | None = None,
        model: ServoModel | str | None = None,
        params: str | os.PathLike[str] | ServoParams | None = None,
        faults: FaultConfig | None = None,
        seed: int | None = None,
        trace: str | None = None,
        pace: bool = False,
        echo: bool = False,
        name: str | None = None,
        tcp_address: tuple[str, int] = ("127.0.0.1", 0),
        web: str | tuple[str, int] | bool | None = None,
        allow_remote: bool = False,
        servo: str | None = None,
        baud_bps: float | None = None,
    ) -> None:
        if transport not in TRANSPORTS:
            raise ValueError(f"unknown transport {transport!r}; choose one of: {', '.join(TRANSPORTS)}")
        if transport == "inprocess" and (pace or echo):  # the link hands over whole packets: there is no wire to pace or echo
            raise ValueError("pace and echo act on a wire (transport 'pty' or 'tcp'); the in-process link has none")
        _check_types(options=options, model=model, faults=faults, servo=servo, baud_bps=baud_bps)
        if isinstance(tcp_address, str):  # "HOST:PORT", as web= and serve --tcp take it
            from ax12emu.serve.transports.tcp import parse_host_port

            tcp_address = parse_host_port(tcp_address)
        if transport == "tcp":
            _check_local("tcp_address", tcp_address, allow_remote)
        web_address = _web_address(web)
        _check_local("web", web_address, allow_remote)
        if name is not None and transport == "inprocess":
            check_name(name)  # the port is ax12emu://NAME: a name the URL reads otherwise is a port to another bus or none
        elif name is not None and not str(name).strip():
            raise ValueError(f"name {name!r} is blank; leave it out for an automatic one")
        if servo is not None and ids is not None and ":" in servo:
            raise ValueError(f"ids= and the per-ID servo text {servo!r} both name the IDs; give one of them")
        if options is None:
            # In virtual time the clock stands still between steps, so a servo busy after an EEPROM write (6 ms a
            # byte by default) would not answer again until bus.step(): none here, as ax12emu://?virtual_time=1.
            options = ServoOptions(eeprom_busy_s_per_byte=0.0) if virtual_time else ServoOptions()
            given_options = False
        else:
            given_options = True
        self.transport_name = transport
        self.virtual_time = virtual_time
        if virtual_time and time_scale != 1.0:  # a virtual clock runs only when stepped: the scale was ignored
            raise ValueError("time_scale applies to the wall clock; with virtual_time=True time moves by step()")
        clock = VirtualClock() if virtual_time else WallClock(time_scale)
        self.bus: AnyBus
        if servo is not None:
            if model is not None and not isinstance(model, str):
                raise ValueError("model: a model object cannot serve a servo= wire (its buses build their own); "
                                 "give model='kinematic' or params= for its AX servos")
            # ServoOptions, model= and params= shape the wire's AX servos (AX-12A, AX-18A), as on the command line.
            choice1 = None
            if model is not None or params is not None:
                given = {} if params is None else ({"params": params} if isinstance(params, ServoParams) else {"params_path": params})
                choice1 = ModelChoice(name=model or "physical", **given)
            options1 = options if isinstance(options, ServoOptions) and given_options and options != ServoOptions() else None
            if options1 is None and virtual_time and _names_ax(servo, ids):
                options1 = options if isinstance(options, ServoOptions) else ServoOptions(eeprom_busy_s_per_byte=0.0)
            options2 = options if isinstance(options, Servo2Options) else Servo2Options()
            self.bus = build_wire(servo, None if ids is None else _id_list(ids), clock=clock, baud_bps=baud_bps, options=options2,
                                  choice1=choice1, options1=options1)
        else:
            if isinstance(options, Servo2Options):
                raise ValueError("Servo2Options apply with servo= (Protocol 2.0 servos); the AX-12A bus takes ServoOptions")
            slots = [1] if ids is None else _id_list(ids)
            if params is not None:  # a parameter file (e.g. a fitted twin's params.toml, effects included) or object
                if model is not None and not isinstance(model, str):
                    raise ValueError("params= builds the physical model; it cannot go with a model object")
                given = {"params": params} if isinstance(params, ServoParams) else {"params_path": params}
                model = build_model(ModelChoice(name=model or "physical", profile=options.profile, **given), len(slots))
            elif isinstance(model, str):
                model = build_model(ModelChoice(name=model, profile=options.profile), len(slots))
            self.bus = Bus(slots, options=options, model=model, clock=clock)
            if baud_bps is not None:  # each servo's Baud Rate, as servo="ax-12a" sets it, so a suite pins its rate
                for each in self.bus.servos:  # whatever model pytest --ax12-servo serves instead
                    start_at_baud(each, baud_bps)
        seed = _fault_seed(seed, faults)
        faults = faults if faults is None or faults.seed == seed else dataclasses.replace(faults, seed=seed)
        self.seed = seed
        if faults is not None and faults.active:
            faults.install(self.bus)
        if trace is not None and not str(trace).strip():  # an unset variable's "": traced nothing without a word
            raise ValueError("trace= names no file (an empty path); leave it out for no trace")
        self._trace_path = trace
        self._pace, self._echo = pace, echo
        self._tcp_address = tcp_address
        #: Where to serve the live view (ax12emu.live): True for loopback on a free port, "HOST:PORT" or a pair.
        self._web_address = web_address
        self._allow_remote = allow_remote
        self._live: Any = None
        #: No name given: an automatic one, which start() replaces should another bus have taken it meanwhile.
        self._auto_name = name is None
        self.name = _next_name() if name is None else name
        self.port = ""
        self._trace: TraceWriter | None = None
        self._transport: Any = None
        self._server: Any = None
        self._link: InProcessLink | None = None
        self._thread: threading.Thread | None = None
        #: The control methods shared with the live view of ``ax12emu serve`` (one body for both).
        self._controls = ServedControls(self.call, servos=len(self.bus.slots), seed=seed)
        #: The servo text the bus was built from (None: AX-12As of ``ids``), which a trace's header keeps.
        self._servo_spec = servo
        self._closed = self._closing = False
        self._started = False
        #: Releases what start() opened should the bus be collected unclosed (see the class docstring).
        self._finalizer: weakref.finalize | None = None
        self._dropped = _Dropped()

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> "VirtualBus":
        """Open the transport and start serving; on failure everything opened is closed."""
        if self._closed:
            raise RuntimeError(f"VirtualBus {self.name} is closed; make a new one")
        if self._started:
            return self
        self._started = True
        try:
            if self._trace_path:
                self._trace = self._open_trace(self._trace_path)
            if self.transport_name == "inprocess":
                self._start_link()
            else:
                self._start_wire()
            self._start_live()
        except BaseException:
            self.close()
            raise
        self._finalizer = weakref.finalize(self, _release_dropped, self._held(), self._dropped)
        self._finalizer.atexit = False  # a bus still held at exit ends with the process, as its daemon thread does
        return self

    def _start_link(self) -> None:
        """Register the in-process link under the bus's name (a free one, when the name was automatic)."""
        if self._trace is not None:
            self._trace.note(echo=False)  # the decoder then never takes a repeated poll for an echo
        link = InProcessLink(self.bus, trace=self._trace)
        while True:
            try:
                register(self.name, link)  # a name another bus holds is refused here, and that bus keeps it
                break
            except NameTaken:
                if not self._auto_name:
                    raise
                self.name = _next_name()
        self._link = link
        self.port = f"ax12emu://{self.name}"

    def _start_wire(self) -> None:
        """Open the pty or TCP port and start the serving thread on it."""
        from ax12emu.serve import BusServer, open_transport
        from ax12emu.serve.transports.tcp import address_error, is_loopback

        if self.transport_name == "pty":
            self._transport = open_transport("pty")
        else:
            host, port = self._tcp_address
            try:
                self._transport = open_transport("tcp", host=host, port=port)
            except OSError as exc:
                raise address_error("tcp_address", (host, port), exc) from None

            if not is_loopback(host):  # (allow_remote=True): said, as serve --allow-remote says it
                log.warning("VirtualBus %s serving on %s, reachable from other machines", self.name, self._transport.url)
        self.port = self._transport.url
        self._server = BusServer(self.bus, self._transport, pace=self._pace, echo=self._echo, trace=self._trace)
        self._thread = threading.Thread(target=_serve, args=(self._server, self.name, self._dropped), name=f"ax12emu-{self.name}",
                                        daemon=True)
        self._thread.start()

    def _held(self) -> _Held:
        return _Held(self.name, self.bus, live=self._live, server=self._server, thread=self._thread, link=self._link,
                     transport=self._transport, trace=self._trace)

    def _open_trace(self, path: str) -> TraceWriter:
        if self._servo_spec is not None:  # every servo's model, so ax12emu decode names each ID's registers by its table
            return TraceWriter(path, servos=servo_list(self.bus))
        return TraceWriter(path, profile=self.bus.options.profile)

    def _start_live(self) -> None:
        """The live page (``web=...``) of any wire: sampled through :meth:`call`; its controls are this object's methods;
        its packet log names each servo's registers by its model's table (``decoder_options``)."""
        if self._web_address is None:
            return
        from ax12emu.live import ByteTap, LiveView
        from ax12emu.live.buses import decoder_options
        from ax12emu.serve.transports.tcp import address_error

        # Its threads hold the bus weakly: a page left open must not keep a dropped bus from being collected.
        controls = weakref.proxy(self)
        if self._link is not None:
            link = self._link
            tap = ByteTap(link.trace)
            link.trace = tap
            self._live = LiveView(
                _weak_call(weakref.ref(self), self._dropped), controls=controls, tap=tap, counters=lambda: {"packets_in": link.packets_in},
                web=self._web_address, allow_remote=self._allow_remote, echo=False, **self.call(decoder_options),
            )
        else:
            self._live = LiveView.for_server(self._server, controls=controls, web=self._web_address, allow_remote=self._allow_remote)
        try:
            self._live.start()
        except OSError as exc:
            raise address_error("web", self._web_address, exc) from None

    @property
    def web_url(self) -> str | None:
        """The live page's address (``VirtualBus(web=True)``), or None."""
        return None if self._live is None else self._live.url

    def close(self) -> None:
        """Stop serving, join the thread, close the port and the trace; safe to call more than once."""
        if self._closing:
            return
        self._closing = True  # (the live view, closing first, may still read the bus through call)
        if self._finalizer is not None:
            self._finalizer.detach()
        _release(self._held())
        self._closed = True

    @property
    def running(self) -> bool:
        """Whether clients can talk to the bus now."""
        if self._closed or not self._started:
            return False
        return self._link is not None or (self._thread is not None and self._thread.is_alive())

    def __enter__(self) -> "VirtualBus":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- running code where the bus lives ---------------------------------------------------
    def call(self, fn: Callable[[Bus], Any], timeout_s: float | None = None) -> Any:
        """Run ``fn(bus)`` between packets (on the serving thread, or under the link's lock); served on a pty or
        TCP, wait at most ``timeout_s`` for it (default :data:`_CALL_TIMEOUT_S`).

        On the wall clock ``fn`` sees the bus as it is now: the in-process link brings the physics up to the
        present first, as the serving loop keeps it.  RuntimeError once the bus is closed, also for a call
        waiting on the serving thread when it closes.
        """
        if self._closed:  # its port is gone (a pty's name may be another's by now) and its state was saved
            raise RuntimeError(f"VirtualBus {self.name} is closed")
        if self._link is not None:
            return self._link.call(fn, advance=not self.virtual_time)
        if self._thread is not None:
            if threading.current_thread() is self._thread:  # a call from inside a call (fn using this bus's methods):
                return fn(self.bus)  # it is between packets already; queued, it waited for itself 5 s
            if self._thread.is_alive():
                from ax12emu.serve.server import ServerStopped

                try:
                    return self._server.call(fn, _CALL_TIMEOUT_S if timeout_s is None else timeout_s)
                except ServerStopped:
                    raise RuntimeError(f"VirtualBus {self.name} is closed") from None
            if self._closing:  # the loop has ended and close() is tearing the bus down under this thread
                raise RuntimeError(f"VirtualBus {self.name} is closed")
        return fn(self.bus)

    def _faults(self, bus: Bus) -> Faults:
        return self._controls.faults_of(bus)

    @property
    def faults(self) -> Any:
        """The bus's :class:`~ax12emu.faults.injection.Faults` (created on first use); methods take slots."""
        return _FaultsOnBus(self)

    # -- time ----------------------------------------------------------------------------------
    def step(self, seconds: float) -> float:
        """Advance virtual time by ``seconds`` and run the physics; returns the new time."""
        if not self.virtual_time:
            raise RuntimeError("step() needs VirtualBus(virtual_time=True); this bus follows the wall clock")
        if not math.isfinite(float(seconds)):  # (inf overflowed the serving thread's wait, as an OverflowError)
            raise ValueError(f"time moves by a finite step, got seconds={seconds!r}")

        def _step(bus: Bus) -> float:
            now = bus.clock.advance(seconds)  # type: ignore[union-attr]
            bus.advance()
            return now

        # Served on a pty or TCP the step runs on the serving thread: it may take a while for a long one (the
        # physics runs many times faster than real time, so a wall second per simulated second is ample).
        return self.call(_step, timeout_s=_CALL_TIMEOUT_S + max(0.0, float(seconds)))

    @property
    def now_s(self) -> float:
        """Simulated time."""
        return self.bus.clock.now_s()

    # -- servo state ---------------------------------------------------------------------------
    def read(self, servo_id: int, name: str, *, protocol: float | None = None) -> int:
        """A register by name (the servo model's table's names), as a client would read it now.

        ``protocol``: 1.0 or 2.0, needed on a mixed wire for an ID both protocols have.
        """

        def _read(bus: AnyBus) -> int:
            holder, servo = _servo_with(bus, servo_id, name, protocol)
            _as_a_request_finds_it(holder)
            return servo.table.get(name)

        return self.call(_read)

    def write(self, servo_id: int, name: str, value: int, *, protocol: float | None = None) -> None:
        """Set a register as the firmware would (no access or range check); an ``id`` write moves the servo."""

        def _write(bus: Bus) -> None:
            _, servo = _servo_with(bus, servo_id, name, protocol)
            servo.table.set(name, _fitting(servo.table.layout.by_name[name], value))  # the AX-12 bus's plant hears of it
            if _firmware(servo) is not None:  # a firmware of its own takes its commands when told
                servo.plant.command(goal_written=name in _GOAL_REGISTERS)
            if name == "id":
                bus.reindex()

        self.call(_write)

    def table(self, servo_id: int, *, protocol: float | None = None) -> dict[str, int]:
        """Every register by name."""

        def _table(bus: Bus) -> dict[str, int]:
            holder, servo = _find(bus, servo_id, protocol)
            _as_a_request_finds_it(holder)
            table = servo.table
            return {e.name: table.get(e.name) for e in table.layout.entries}

        return self.call(_table)

    def angle_deg(self, servo_id: int, *, protocol: float | None = None) -> float:
        """The simulated shaft angle in degrees from the CW end (0..300 over positions 0..1023).

        On a servo with a firmware model of its own (the X and MX series): the output shaft's angle as
        its physics counts it (turns included; 180 at the start, where an X-series Present Position reads
        2048 and an MX's Present Position 2048).
        """

        def _angle(bus: AnyBus) -> float:
            holder, servo = _find(bus, servo_id, protocol)
            firmware = _firmware(servo)
            if firmware is not None:
                physics = getattr(firmware, "physics", None)
                if physics is None:
                    raise NotImplementedError(f"{type(firmware).__name__} does not show its shaft angle (no physics)")
                return float(physics.angle_rad) * _DEG_PER_RAD
            return float(holder.model.angle_rad[servo.index]) * _DEG_PER_RAD

        return self.call(_angle)

    def set_angle_deg(self, servo_id: int, degrees: float, *, protocol: float | None = None) -> None:
        """Move the shaft by hand (torque off, or the controller pulls it back): an AX-12's, whose bus's model sets angles."""
        _finite("degrees", degrees)

        def _set(bus: AnyBus) -> None:
            holder, servo = _find(bus, servo_id, protocol)
            model = getattr(holder, "model", None)
            if not isinstance(model, AngleSettable):
                what = type(model).__name__ if model is not None else f"the firmware model of {model_name(servo)}"
                raise NotImplementedError(f"set_angle_deg: {what} does not let its angle be set (ID {servo_id}, "
                                          f"on a Protocol {holder.protocol} bus)")
            model.set_angle(servo.index, degrees / _DEG_PER_RAD)
            holder.plant.tables_changed()
            holder.plant.refresh()

        self.call(_set)

    def temperature_c(self, servo_id: int, *, protocol: float | None = None) -> int:
        """Present Temperature, degrees C."""
        return self.read(servo_id, "present_temperature", protocol=protocol)

    def _hold(self, servo_id: int, protocol: float | None, names: tuple[str, ...], value: int | None) -> None:
        """Pin a reading through the faults of the servo's own bus: the first of ``names`` its table has."""

        def _pin(bus: AnyBus) -> None:
            holder, servo = _find(bus, servo_id, protocol)
            name = next((n for n in names if n in servo.table.layout.by_name), None)
            if name is None:
                raise KeyError(f"{model_name(servo)} has no register {' or '.join(map(repr, names))} (ID {servo_id})")
            if value is not None:
                _fitting(servo.table.layout.by_name[name], value)
            self._controls.faults_of(bus)  # the whole wire's faults first: one seed for all its servos
            self._controls.faults_of(holder).hold(holder.slots[servo.index], name, value)

        self.call(_pin)

    def set_temperature(self, servo_id: int, celsius: float | None, *, protocol: float | None = None) -> None:
        """Pin Present Temperature (above Temperature Limit: Overheating); None releases it.

        On an X-series servo the firmware judges the pinned reading: Overheating latches if Shutdown
        selects it, and stays until REBOOT after the reading is released.
        """
        value = None if celsius is None else round(_finite("celsius", celsius))
        self._hold(servo_id, protocol, ("present_temperature",), value)

    def set_voltage(self, servo_id: int, volts: float | None, *, protocol: float | None = None) -> None:
        """Pin Present Voltage (outside the voltage limits: Input Voltage error); None releases it.

        On an X-series servo: Present Input Voltage (144), judged by the firmware as
        :meth:`set_temperature` says.
        """
        value = None if volts is None else round(_finite("volts", volts) * 10)
        self._hold(servo_id, protocol, ("present_voltage", "present_input_voltage"), value)

    def set_external_torque(self, servo_id: int, torque_nm: float, *, protocol: float | None = None) -> None:
        """A torque on the output shaft (N m, positive CCW), through the model's ``set_external_torque``."""

        _finite("torque_nm", torque_nm)

        def _own_firmware(bus: AnyBus) -> bool:
            firmware = _firmware(_find(bus, servo_id, protocol)[1])
            if firmware is not None:
                firmware.set_external_torque(torque_nm)
            return firmware is not None

        if not self.call(_own_firmware):  # an AX-12: its bus's one model takes every servo's torque (ServedControls)
            self._controls.set_external_torque(servo_id, torque_nm, protocol=1.0)


def _finite(name: str, value: float) -> float:
    """``value`` as a float; ValueError for NaN or infinity, which would stick in the physics for good."""
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return number


def _fitting(entry: Any, value: Any) -> int:
    """``value`` as an int that the register ``entry`` holds (numpy integers too); ValueError for one it cannot hold
    (it wrapped: an ID of 300 became 44), naming the register and what it holds.  No range check beyond its bytes:
    a test may set what the firmware could."""
    try:
        number = operator.index(value)
    except TypeError:
        raise TypeError(f"{entry.name} takes an integer, got {type(value).__name__} {value!r}") from None
    low, high = entry.byte_range
    if not low <= number <= high:
        raise ValueError(f"{entry.name} holds {low}..{high} ({entry.size} byte{'s' if entry.size > 1 else ''}), got {number}")
    return number


def _names_ax(servo: str, ids: Iterable[int] | None) -> bool:
    """Whether the servo text puts AX servos (AX-12A, AX-18A) on the wire: their bus takes ServoOptions.  False
    for a text that does not parse, which the wire's builder then refuses naming the mistake."""
    from ax12emu.bus.wire import servo_family, servo_models

    try:
        return any(servo_family(key) == "AX" for _, key in servo_models(servo, None if ids is None else _id_list(ids), mixed=True))
    except (ValueError, KeyError, TypeError):
        return False


def _id_list(ids: Iterable[Any]) -> list[int]:
    """The IDs as Python ints (numpy's integers too); TypeError naming one that is not an integer."""
    try:
        return [operator.index(servo_id) for servo_id in ids]
    except TypeError:
        raise TypeError(f"ids must be integers, got {ids!r}") from None
