"""Servo models as data: one TOML file per model, read and checked here.

Why it exists: a servo model (AX-12A, MX-28, XL430-W250, ...) is its control table, its identity
(model number, firmware, protocol) and its data-sheet physics, and all of that is data quoted from
the ROBOTIS e-manual: adding a model is adding a file under ``ax12emu/protocol/models/``, no code.
Every file is checked on load; a mistake gets a ``ValueError`` naming the file and the field.

The format (``models/ax-12a.toml`` is the worked example)::

    [model]
    name = "XL430-W250"          # as ROBOTIS writes it
    model_number = 1060          # must equal the table's model_number default
    firmware_version = 45        # optional: the value the emulated servo reports
    baud_rates_bps = [9600, 57600, 115200, 1000000]  # optional: bit rate per Baud Rate register value
    protocols = ["2.0"]          # "1.0" and/or "2.0": the protocol this table is for
    source = "..."               # e-manual page and the emanual repository commit
    unsupported_instructions = ["clear"]  # optional: Protocol 2.0 instructions the model's firmware does not
                                 # know (Instruction2 names), where the e-manual's "Supported DYNAMIXEL" lists leave it out
    broadcast_reset_all = "refused"  # optional: "executed" where a broadcast Factory Reset 0xFF resets every servo

    [table]
    size = 662                   # bytes: addresses 0 .. size-1
    entries = [                  # one inline table per register, in the e-manual's order
      { address = 0, size = 2, name = "model_number", access = "R", area = "EEPROM", default = 1060 },
      { address = 20, size = 4, name = "homing_offset", access = "RW", area = "EEPROM", default = 0, min = -1044479, max = 1044479, signed = true },
      { address = 168, size = 2, count = 28, name = "indirect_address_{n}", access = "RW", area = "RAM", default = 224, default_step = 1, min = 64, max = 661 },
    ]

    [profiles.NAME]              # optional; without any, one profile named after the file
    source = "..."
    overrides = { punch = { min = 32 } }       # default / min / max per entry
    extra_entries = [ ... ]                    # entries only this profile has
    lock_writable = [24, 50]                   # [first, end) a WRITE may touch while Lock is 1 (tables
                                               # with a lock register; default: the RAM area)
    shutdown_clears = "torque_limit"           # or "torque_enable": what Alarm Shutdown clears, where
                                               # the source says (absent: not stated)

    [physical]
    source = "..."
    gear_ratio = 353.5
    weight_g = 57.2
    resolution_deg = 0.088
    position_range_deg = 360
    operating_voltage_v = [6.5, 12.0]
    recommended_voltage_v = 11.1
    ratings = [ { voltage_v = 12.0, stall_torque_nm = 1.5, stall_current_a = 1.4, no_load_speed_rpm = 61 } ]
    current_unit_ma = 2.69       # optional: Goal/Present Current's unit, where the table has them
    rotor_inertia_at_motor_kg_m2 = 2e-8   # optional: the motor's rotor (else the AX-12A's, scaled by the gearing,
                                 # on the AX models; on the X-series firmware model, scaled by the motor's kind)
    motor = "coreless"           # optional: the e-manual's "Motor" row, "cored" (absent: cored) or "coreless"
                                 # ("Coreless", "Coreless(Maxon)", "Coreless DC"): how the X-series model scales its rotor

    [controller]                 # optional: how a real unit's control loop departs from the e-manual
    source = "..."               # the measurement that shows it
    position_output_scale = 0.5  # the position PID's output per the e-manual's gain conversion, times this

    [mode_change]                # optional: what a write that changes Operating Mode(11) resets
    source = "..."               # the e-manual's sentence
    defaults = ["velocity_i_gain", "profile_velocity"]   # back to their table default
    from_registers = { goal_pwm = "pwm_limit" }          # set to that register's present value

    [classic]                    # optional: a classic table (AX/MX/XL-320 registers) run on the X-series
    source = "..."               # firmware model; what its units are (ax12emu.servo.classic maps them)
    position_units = 1024        # Goal/Present Position units over position_span_deg ...
    position_span_deg = 300.0
    position_centre = 512        # ... and the value at the middle of that span
    speed_unit_rpm = 0.111       # Moving Speed / Present Speed unit (joint mode)
    direction_bit = 10           # the sign bit of Moving Speed (wheel), Present Speed and Present Load
    output_full_scale = 1023     # Torque Limit, wheel-mode Moving Speed and Present Load: 1023 = 100 %
    wheel_output = "pwm"         # wheel-mode Moving Speed: "pwm" (output share) or "velocity" (speed_unit_rpm)
    mode_register = "control_mode"  # optional: the register choosing wheel mode (absent: both angle
    wheel_modes = [1]               # limits 0, the AX/MX rule) and its wheel-mode values
    p_gain_factor = 0.125        # optional, for tables with P/I/D gains: the e-manual's controller
    i_gain_factor_s = 0.48828125 # gains per register unit (Kp = P/8, Ki = I*1000/2048 per second,
    d_gain_factor_s = 0.004      # Kd = D*4/1000 seconds), output in output_full_scale units per position unit
    errors = { overload = 1, overheating = 2, input_voltage = 4 }  # Shutdown / Hardware Error Status bits
    acceleration_unit_deg_s2 = 8.583  # optional: Goal Acceleration's unit (the MX series)
    multi_turn_limit = 4095      # optional, with the next: both angle limits at it select multi-turn mode,
    multi_turn_goal_limit = 28672  # whose Goal Position takes -28,672..28,672 (the MX series)

Entry keys: ``address``, ``size`` (1, 2 or 4), ``name`` (snake_case, unique), ``access`` ("R" or "RW"),
``area`` ("EEPROM" or "RAM"; EEPROM entries come before the first RAM one), ``default`` (absent: the
e-manual gives none, "-", and 0 is used), ``min``/``max`` (absent: the full span of the size, signed or
not), ``signed``, ``min_from``/``max_from`` (a register bounding this one at run time, "-" to negate),
``count``/``first``/``default_step`` (a run of equal registers such as Indirect Address 1..28: ``{n}``
in the name counts from ``first``, default 1), ``note`` (free text, for readers), ``ranges_when`` (ranges
another register selects: ``[{ register = "operating_mode", values = [4], min = -1048575, max = 1048575,
limits = false }]``, ``limits`` saying whether ``min_from``/``max_from`` still apply), ``values`` (the only
values a write may give, where the source lists them: Operating Mode's modes).
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from .packets2 import Instruction2
from .registers import MAX_ENTRY_SIZE, Access, Area, Entry, Layout, ModeRange, Profile, compile_layout

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the same parser, from PyPI
    import tomli as tomllib

__all__ = ["Rating", "Physical", "Controller", "Classic", "CLASSIC_ERRORS", "ServoModel", "parse_model", "load_model_file", "model", "model_names", "MODELS_PACKAGE_DIR"]

#: Where the shipped model files live (package data).
MODELS_PACKAGE_DIR = "models"
PROTOCOLS = ("1.0", "2.0")
SHUTDOWN_CLEARS = ("torque_limit", "torque_enable")
#: Instructions every Protocol 2.0 firmware knows (and the status packet's code): a model file cannot leave them out.
_ALWAYS_KNOWN = frozenset({Instruction2.PING, Instruction2.READ, Instruction2.WRITE, Instruction2.STATUS})

_MODEL_KEYS = {"name", "model_number", "firmware_version", "protocols", "source", "baud_rates_bps",
               "unsupported_instructions", "broadcast_reset_all"}
#: What a Protocol 2.0 firmware does with Factory Reset 0xFF (reset all) to the broadcast ID.
BROADCAST_RESET_ALL = ("refused", "executed")
_TABLE_KEYS = {"size", "entries"}
_ENTRY_KEYS = {"address", "size", "name", "access", "area", "default", "min", "max", "signed", "min_from", "max_from",
               "count", "first", "default_step", "note", "ranges_when", "values"}
_RANGE_WHEN_KEYS = {"register", "values", "min", "max", "limits"}
_PROFILE_KEYS = {"source", "overrides", "extra_entries", "lock_writable", "shutdown_clears"}
_OVERRIDE_KEYS = {"default": "default", "min": "minimum", "max": "maximum"}
_PHYSICAL_KEYS = {"source", "gear_ratio", "weight_g", "resolution_deg", "position_range_deg", "operating_voltage_v",
                  "recommended_voltage_v", "ratings", "current_unit_ma", "rotor_inertia_at_motor_kg_m2", "motor"}
#: The e-manual's "Motor" kinds a model file may name (every coreless kind it prints is "coreless" here); the same
#: as firmware_model.xseries.physics.MOTOR_KINDS, which this layer may not import (a test holds them equal).
MOTOR_KINDS = ("cored", "coreless")
_RATING_KEYS = {"voltage_v", "stall_torque_nm", "stall_current_a", "no_load_speed_rpm", "note"}
_CONTROLLER_KEYS = {"source", "position_output_scale"}
_MODE_CHANGE_KEYS = {"source", "defaults", "from_registers"}
_CLASSIC_KEYS = {"source", "position_units", "position_span_deg", "position_centre", "speed_unit_rpm", "direction_bit",
                 "output_full_scale", "wheel_output", "mode_register", "wheel_modes", "p_gain_factor", "i_gain_factor_s",
                 "d_gain_factor_s", "errors", "acceleration_unit_deg_s2", "multi_turn_limit", "multi_turn_goal_limit"}
#: What a classic table's error bits may name (the X-series firmware's protections).
CLASSIC_ERRORS = ("input_voltage", "overheating", "overload")
#: Wheel-mode Moving Speed: a share of the output (AX, XL-320: "only the output control is possible") or a speed.
CLASSIC_WHEEL_OUTPUTS = ("pwm", "velocity")


@dataclass(frozen=True)
class Rating:
    """One data-sheet operating point: stall torque and no-load speed at a stated supply."""

    voltage_v: float
    stall_torque_nm: float
    no_load_speed_rpm: float
    stall_current_a: float | None = None

    @property
    def no_load_speed_rad_s(self) -> float:
        """The no-load speed in SI units."""
        return self.no_load_speed_rpm * 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class Physical:
    """Data-sheet physics of a model, each figure as the source states it."""

    source: str
    gear_ratio: float
    ratings: tuple[Rating, ...]
    operating_voltage_v: tuple[float, float]
    recommended_voltage_v: float | None = None
    weight_g: float | None = None
    resolution_deg: float | None = None
    position_range_deg: float | None = None
    #: Goal/Present Current's unit, mA (X series with current sensing); None where the table has no current.
    current_unit_ma: float | None = None
    #: The motor's rotor inertia at the motor shaft, kg m^2; None: no source gives it (the physics assumes the AX-12A's).
    rotor_inertia_at_motor_kg_m2: float | None = None
    #: The e-manual's "Motor" row: "cored" or "coreless"; the X-series physics scales a rotor no source gives by
    #: BAM's fits of that kind of motor (absent from the file: "cored").
    motor: str = "cored"

    def rating_at(self, voltage_v: float | None = None) -> Rating:
        """The rating at ``voltage_v``, or at the recommended supply, or the first one listed."""
        want = self.recommended_voltage_v if voltage_v is None else voltage_v
        for rating in self.ratings:
            if want is not None and rating.voltage_v == want:
                return rating
        if voltage_v is not None:
            raise ValueError(f"no rating at {voltage_v} V; the data sheet gives {[r.voltage_v for r in self.ratings]}")
        return self.ratings[0]


@dataclass(frozen=True)
class Controller:
    """Where a real unit's control loop was measured to depart from the e-manual's description (absent: it does not)."""

    source: str = ""
    #: Factor on the position controller's output after the e-manual's gain conversion (1: as the e-manual reads).
    position_output_scale: float = 1.0


@dataclass(frozen=True)
class ModeChange:
    """What the firmware resets when a write changes Operating Mode(11) (``[mode_change]``; empty: nothing)."""

    source: str = ""
    #: Registers put back to their table default.
    defaults: tuple[str, ...] = ()
    #: (register, source register): the register takes the source register's present value.
    from_registers: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class Classic:
    """A classic control table's units (``[classic]``), so the X-series firmware model can run it.

    Why data: the XL-320 and the MX series keep the AX series' registers (Goal Position, Moving Speed,
    Torque Limit, P/I/D gains) with each family's own units; :mod:`ax12emu.servo.classic` translates
    whichever numbers the file gives.
    """

    source: str
    #: Goal/Present Position: ``position_units`` over ``position_span_deg``, ``position_centre`` at its middle.
    position_units: int
    position_span_deg: float
    position_centre: int
    #: Moving Speed (joint mode) and Present Speed unit, rpm.
    speed_unit_rpm: float
    #: Sign bit of wheel-mode Moving Speed, Present Speed and Present Load (set: clockwise).
    direction_bit: int = 10
    #: Torque Limit, wheel-mode Moving Speed (where ``wheel_output`` is "pwm") and Present Load: this value is 100 %.
    output_full_scale: int = 1023
    #: What wheel-mode Moving Speed sets: "pwm" (a share of the output) or "velocity" (``speed_unit_rpm``).
    wheel_output: str = "pwm"
    #: The register choosing wheel mode and its wheel values; None: wheel mode is both angle limits 0.
    mode_register: str | None = None
    wheel_modes: tuple[int, ...] = ()
    #: The e-manual's controller gains per register unit (None: the table has no such gain).
    p_gain_factor: float | None = None
    i_gain_factor_s: float | None = None
    d_gain_factor_s: float | None = None
    #: (protection, bit) of Shutdown and Hardware Error Status; protections from :data:`CLASSIC_ERRORS`.
    errors: tuple[tuple[str, int], ...] = ()
    #: Goal Acceleration's unit, deg/s^2 (the MX series: 8.583); None: the table has no goal acceleration.
    acceleration_unit_deg_s2: float | None = None
    #: CW and CCW Angle Limit both at this value select multi-turn mode (the MX series: 4095); None: no such mode.
    multi_turn_limit: int | None = None
    #: Goal Position's range in multi-turn mode: -this .. this (the MX series: 28,672).
    multi_turn_goal_limit: int = 0


@dataclass(frozen=True)
class ServoModel:
    """One servo model, as its data file states it."""

    #: The file's stem, the name a caller asks for ("ax-12a").
    key: str
    name: str
    model_number: int
    firmware_version: int | None
    protocols: tuple[str, ...]
    source: str
    table_size: int
    entries: tuple[Entry, ...]
    profiles: Mapping[str, Profile]
    physical: Physical
    #: The file it came from, for messages.
    path: str = ""
    #: Bit rate for each Baud Rate register value (index = value); empty where the file gives none
    #: (the Protocol 1.0 models compute theirs: 2 Mbps / (value + 1)).
    baud_rates_bps: tuple[int, ...] = ()
    #: Measured departures of the control loop from the e-manual (``[controller]``).
    controller: Controller = Controller()
    #: What a change of Operating Mode(11) resets (``[mode_change]``).
    mode_change: ModeChange = ModeChange()
    #: A classic table's units (``[classic]``); None for X-series tables and the AX-12's own model.
    classic: Classic | None = None
    #: Protocol 2.0 instruction codes the firmware does not know: answered with Instruction Error, never listed
    #: among a Sync/Bulk Read's answers (``model.unsupported_instructions``).
    unsupported_instructions: frozenset[int] = frozenset()
    #: Factory Reset 0xFF to the broadcast ID: "refused" (not carried out, "MX(2.0) FW42, X-series FW42 or above",
    #: e-manual, Protocol 2.0, Factory Reset) or "executed" (a firmware before that safety feature: every servo
    #: resets, to ID 1) (``model.broadcast_reset_all``).
    broadcast_reset_all: str = "refused"
    _layouts: dict[str, Layout] = field(default_factory=dict, compare=False, repr=False)

    @property
    def default_profile(self) -> str:
        """The first profile in the file (the only one for most models)."""
        return next(iter(self.profiles))

    def layout(self, profile: str | None = None) -> Layout:
        """The compiled table of ``profile`` (default: the first)."""
        name = self.default_profile if profile is None else profile
        if name not in self.profiles:
            raise ValueError(f"unknown profile {name!r} of {self.name}; choose one of: {', '.join(self.profiles)}")
        if name not in self._layouts:
            self._layouts[name] = compile_layout(self.profiles[name], self.entries, self.table_size)
        return self._layouts[name]


# ------------------------------------------------------------------ checking helpers
class _Where:
    """Builds error messages that name the file and the field."""

    def __init__(self, path: str) -> None:
        self.path = path

    def error(self, field_name: str, message: str) -> ValueError:
        return ValueError(f"{self.path}: {field_name}: {message}")

    def table(self, data: Any, field_name: str, known: set[str], required: set[str] = frozenset()) -> dict:
        if not isinstance(data, dict):
            raise self.error(field_name, f"must be a table, got {type(data).__name__}")
        unknown = sorted(set(data) - known)
        if unknown:
            raise self.error(field_name, f"unknown key(s) {unknown}; known: {', '.join(sorted(known))}")
        missing = sorted(required - set(data))
        if missing:
            raise self.error(field_name, f"missing key(s) {missing}")
        return data

    def integer(self, value: Any, field_name: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(field_name, f"must be an integer, got {value!r}")
        return value

    def number(self, value: Any, field_name: str, positive: bool = True) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(field_name, f"must be a finite number, got {value!r}")
        if positive and value <= 0:
            raise self.error(field_name, f"must be positive, got {value!r}")
        return float(value)

    def text(self, value: Any, field_name: str) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.error(field_name, f"must be a non-empty string, got {value!r}")
        return value

    def choice(self, value: Any, field_name: str, choices: tuple[str, ...]) -> str:
        if value not in choices:
            raise self.error(field_name, f"must be one of {', '.join(map(repr, choices))}, got {value!r}")
        return value


def _entries(where: _Where, raw: Any, field_name: str) -> tuple[Entry, ...]:
    """Entries from a list of inline tables, runs (``count``) expanded."""
    if not isinstance(raw, list):
        raise where.error(field_name, f"must be an array of tables, got {type(raw).__name__}")
    out: list[Entry] = []
    for index, item in enumerate(raw):
        label = f"{field_name}[{index}]"
        item = where.table(item, label, _ENTRY_KEYS, {"address", "size", "name", "access", "area"})
        name = where.text(item["name"], f"{label}.name")
        label = f"{field_name}[{index}] ({name})"
        address = where.integer(item["address"], f"{label}.address")
        size = where.integer(item["size"], f"{label}.size")
        if size not in (1, 2, MAX_ENTRY_SIZE) or address < 0:
            raise where.error(f"{label}", f"size must be 1, 2 or 4 and the address >= 0, got size {size} at {address}")
        access = Access(where.choice(item["access"], f"{label}.access", tuple(a.value for a in Access)))
        area = Area(where.choice(item["area"], f"{label}.area", tuple(a.value for a in Area)))
        signed = item.get("signed", False)
        if not isinstance(signed, bool):
            raise where.error(f"{label}.signed", f"must be true or false, got {signed!r}")
        bits = 8 * size
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        minimum = where.integer(item.get("min", low), f"{label}.min")
        maximum = where.integer(item.get("max", high), f"{label}.max")
        if not low <= minimum <= maximum <= high:
            raise where.error(label, f"range {minimum}..{maximum} does not fit {size} byte(s) "
                                     f"({'signed' if signed else 'unsigned'} {low}..{high}) or is empty")
        default = where.integer(item.get("default", 0), f"{label}.default")
        if not minimum <= default <= maximum:
            what = "default" if "default" in item else "default (absent, so 0)"
            raise where.error(f"{label}.default", f"{what} {default} is outside {minimum}..{maximum}")
        bounds = {}
        for key in ("min_from", "max_from"):
            if key in item:
                bounds[key] = where.text(item[key], f"{label}.{key}")
        if "note" in item:
            where.text(item["note"], f"{label}.note")
        modes = _ranges_when(where, item.get("ranges_when", []), f"{label}.ranges_when", low, high)
        allowed = None
        if "values" in item:
            raw_values = item["values"]
            if not isinstance(raw_values, list) or not raw_values:
                raise where.error(f"{label}.values", f"must be a non-empty list of the values a write may give, got {raw_values!r}")
            allowed = tuple(where.integer(v, f"{label}.values") for v in raw_values)
            if any(not minimum <= v <= maximum for v in allowed) or default not in allowed:
                raise where.error(f"{label}.values", f"{list(allowed)} must lie in {minimum}..{maximum} and hold the default {default}")
        count = where.integer(item.get("count", 1), f"{label}.count")
        first = where.integer(item.get("first", 1), f"{label}.first")
        step = where.integer(item.get("default_step", 0), f"{label}.default_step")
        if count < 1:
            raise where.error(f"{label}.count", f"must be >= 1, got {count}")
        if count > 1 and "{n}" not in name:
            raise where.error(f"{label}.name", "a run (count > 1) needs {n} in its name")
        if count == 1 and ("first" in item or "default_step" in item):
            raise where.error(label, "first and default_step belong to a run (count > 1)")
        for k in range(count):
            value = default + k * step
            if not minimum <= value <= maximum:
                raise where.error(f"{label}.default_step", f"copy {first + k} has default {value}, outside {minimum}..{maximum}")
            out.append(Entry(address + k * size, size, name.replace("{n}", str(first + k)), access, value, minimum,
                             maximum, area, signed, bounds.get("min_from"), bounds.get("max_from"), modes, allowed))
    return tuple(out)


def _ranges_when(where: _Where, raw: Any, field_name: str, low: int, high: int) -> tuple[ModeRange, ...]:
    """``ranges_when``: ranges another register selects, each inside the entry's size."""
    if not isinstance(raw, list):
        raise where.error(field_name, f"must be an array of tables, got {type(raw).__name__}")
    out = []
    for index, item in enumerate(raw):
        label = f"{field_name}[{index}]"
        item = where.table(item, label, _RANGE_WHEN_KEYS, {"register", "values", "min", "max"})
        values = item["values"]
        if not isinstance(values, list) or not values:
            raise where.error(f"{label}.values", f"must be a non-empty list of register values, got {values!r}")
        minimum, maximum = where.integer(item["min"], f"{label}.min"), where.integer(item["max"], f"{label}.max")
        if not low <= minimum <= maximum <= high:
            raise where.error(label, f"range {minimum}..{maximum} does not fit the entry ({low}..{high}) or is empty")
        limits = item.get("limits", True)
        if not isinstance(limits, bool):
            raise where.error(f"{label}.limits", f"must be true or false, got {limits!r}")
        out.append(ModeRange(where.text(item["register"], f"{label}.register"),
                             tuple(where.integer(v, f"{label}.values") for v in values), minimum, maximum, limits))
    return tuple(out)


def _check_bounds_names(where: _Where, entries: tuple[Entry, ...], field_name: str) -> None:
    names = {e.name for e in entries}
    for entry in entries:
        for ref in (entry.minimum_from, entry.maximum_from, *(m.register for m in entry.mode_ranges)):
            if ref is not None and ref.lstrip("-") not in names:
                raise where.error(f"{field_name} ({entry.name})", f"bound register {ref!r} is not in the table")


def _profiles(where: _Where, raw: Any, key: str, base: tuple[Entry, ...], table_size: int) -> dict[str, Profile]:
    names = {e.name for e in base}
    ram = [e.address for e in base if e.area is Area.RAM]
    # With a Lock register, by default the RAM area stays writable while Lock is set (the EEPROM freezes).
    default_lock = range(min(ram) if ram else table_size, table_size) if "lock" in names else None
    if raw is None:
        raw = {key: {"source": "the model's table as its file states it"}}
    if not isinstance(raw, dict) or not raw:
        raise where.error("profiles", "must be a table of one or more [profiles.NAME] tables")
    out = {}
    for name, spec in raw.items():
        label = f"profiles.{name}"
        spec = where.table(spec, label, _PROFILE_KEYS, {"source"})
        overrides_raw = spec.get("overrides", {})
        if not isinstance(overrides_raw, dict):
            raise where.error(f"{label}.overrides", "must be a table of entry = { default/min/max = ... }")
        overrides = {}
        for entry_name, change in overrides_raw.items():
            if entry_name not in names:
                raise where.error(f"{label}.overrides.{entry_name}", "no such entry in [table]")
            change = where.table(change, f"{label}.overrides.{entry_name}", set(_OVERRIDE_KEYS))
            overrides[entry_name] = MappingProxyType(
                {_OVERRIDE_KEYS[k]: where.integer(v, f"{label}.overrides.{entry_name}.{k}") for k, v in change.items()}
            )
        extra = _entries(where, spec.get("extra_entries", []), f"{label}.extra_entries")
        lock = default_lock
        if "lock_writable" in spec and "lock" not in names:
            raise where.error(f"{label}.lock_writable", "the table has no lock register")
        if "lock_writable" in spec:
            pair = spec["lock_writable"]
            if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in pair)
                    and 0 <= pair[0] <= pair[1] <= table_size):
                raise where.error(f"{label}.lock_writable", f"must be [first, end] within 0..{table_size}, got {pair!r}")
            lock = range(pair[0], pair[1])
        profile = Profile(
            name=name,
            source=where.text(spec["source"], f"{label}.source"),
            lock_writable=lock,
            overrides=MappingProxyType(overrides),
            extra_entries=extra,
            shutdown_clears=(where.choice(spec["shutdown_clears"], f"{label}.shutdown_clears", SHUTDOWN_CLEARS)
                             if "shutdown_clears" in spec else None),
        )
        try:
            compile_layout(profile, base, table_size)
        except ValueError as exc:
            raise where.error(label, str(exc)) from None
        out[name] = profile
    return out


def _physical(where: _Where, raw: Any) -> Physical:
    raw = where.table(raw, "physical", _PHYSICAL_KEYS, {"source", "gear_ratio", "ratings", "operating_voltage_v"})
    ratings_raw = raw["ratings"]
    if not isinstance(ratings_raw, list) or not ratings_raw:
        raise where.error("physical.ratings", "must be a non-empty array of { voltage_v, stall_torque_nm, no_load_speed_rpm }")
    ratings = []
    for index, item in enumerate(ratings_raw):
        label = f"physical.ratings[{index}]"
        item = where.table(item, label, _RATING_KEYS, {"voltage_v", "stall_torque_nm", "no_load_speed_rpm"})
        current = item.get("stall_current_a")
        ratings.append(Rating(
            voltage_v=where.number(item["voltage_v"], f"{label}.voltage_v"),
            stall_torque_nm=where.number(item["stall_torque_nm"], f"{label}.stall_torque_nm"),
            no_load_speed_rpm=where.number(item["no_load_speed_rpm"], f"{label}.no_load_speed_rpm"),
            stall_current_a=None if current is None else where.number(current, f"{label}.stall_current_a"),
        ))
    span = raw["operating_voltage_v"]
    if not (isinstance(span, list) and len(span) == 2):
        raise where.error("physical.operating_voltage_v", f"must be [low, high], got {span!r}")
    low, high = (where.number(v, "physical.operating_voltage_v") for v in span)
    if low > high:
        raise where.error("physical.operating_voltage_v", f"low {low} above high {high}")
    for rating in ratings:
        if not low <= rating.voltage_v <= high:
            raise where.error("physical.ratings", f"rating at {rating.voltage_v} V is outside the operating range {low}..{high} V")
    optional = {k: where.number(raw[k], f"physical.{k}") for k in
                ("recommended_voltage_v", "weight_g", "resolution_deg", "position_range_deg", "current_unit_ma",
                 "rotor_inertia_at_motor_kg_m2") if k in raw}
    if optional.get("rotor_inertia_at_motor_kg_m2", 1.0) <= 0:
        raise where.error("physical.rotor_inertia_at_motor_kg_m2", f"must be positive, got {optional['rotor_inertia_at_motor_kg_m2']}")
    if "motor" in raw:
        optional["motor"] = where.choice(raw["motor"], "physical.motor", MOTOR_KINDS)
    return Physical(source=where.text(raw["source"], "physical.source"), gear_ratio=where.number(raw["gear_ratio"], "physical.gear_ratio"),
                    ratings=tuple(ratings), operating_voltage_v=(low, high), **optional)


def _baud_rates(where: _Where, raw: Any, register: Entry | None) -> tuple[int, ...]:
    """The bit rate of each Baud Rate register value; every value the register accepts must have one."""
    if raw is None:
        return ()
    if not isinstance(raw, list) or not raw:
        raise where.error("model.baud_rates_bps", f"must be a non-empty list of bit rates, got {raw!r}")
    rates = tuple(where.integer(v, "model.baud_rates_bps") for v in raw)
    if any(rate <= 0 for rate in rates):
        raise where.error("model.baud_rates_bps", f"bit rates must be positive, got {list(rates)}")
    if register is not None and register.maximum >= len(rates):
        raise where.error("model.baud_rates_bps", f"{len(rates)} rates, but baud_rate accepts values up to {register.maximum}")
    return rates


def _controller(where: _Where, raw: Any) -> Controller:
    if raw is None:
        return Controller()
    raw = where.table(raw, "controller", _CONTROLLER_KEYS, {"source"})
    scale = where.number(raw.get("position_output_scale", 1.0), "controller.position_output_scale")
    if not scale > 0:
        raise where.error("controller.position_output_scale", f"must be positive, got {scale}")
    return Controller(source=where.text(raw["source"], "controller.source"), position_output_scale=scale)


def _mode_change(where: _Where, raw: Any, names: Mapping[str, Entry]) -> ModeChange:
    if raw is None:
        return ModeChange()
    raw = where.table(raw, "mode_change", _MODE_CHANGE_KEYS, {"source"})
    if "operating_mode" not in names:
        raise where.error("mode_change", "the table has no operating_mode register")

    def known(name: Any, field_name: str) -> str:
        name = where.text(name, field_name)
        if name not in names:
            raise where.error(field_name, f"no register named {name!r} in the table")
        return name

    defaults = raw.get("defaults", [])
    if not isinstance(defaults, list):
        raise where.error("mode_change.defaults", f"must be a list of register names, got {defaults!r}")
    pairs = raw.get("from_registers", {})
    if not isinstance(pairs, dict):
        raise where.error("mode_change.from_registers", f"must be a table of register = source register, got {pairs!r}")
    return ModeChange(
        source=where.text(raw["source"], "mode_change.source"),
        defaults=tuple(known(name, "mode_change.defaults") for name in defaults),
        from_registers=tuple((known(name, "mode_change.from_registers"), known(src, "mode_change.from_registers"))
                             for name, src in pairs.items()))


def _classic(where: _Where, raw: Any, names: Mapping[str, Entry]) -> Classic | None:
    if raw is None:
        return None
    raw = where.table(raw, "classic", _CLASSIC_KEYS, {"source", "position_units", "position_span_deg", "position_centre",
                                                      "speed_unit_rpm"})
    units = where.integer(raw["position_units"], "classic.position_units")
    centre = where.integer(raw["position_centre"], "classic.position_centre")
    if units < 2 or not 0 <= centre < units:
        raise where.error("classic", f"position_centre {centre} must lie in 0..position_units-1 ({units - 1})")
    span = where.number(raw["position_span_deg"], "classic.position_span_deg")
    if span > 360.0:
        raise where.error("classic.position_span_deg", f"at most one turn (360), got {span}")
    bit = where.integer(raw.get("direction_bit", 10), "classic.direction_bit")
    full = where.integer(raw.get("output_full_scale", 1023), "classic.output_full_scale")
    if not 1 <= bit <= 15 or not 0 < full < (1 << bit):
        raise where.error("classic", f"output_full_scale {full} must fit below direction_bit {bit} (1..15)")
    mode_register = raw.get("mode_register")
    wheel_modes: tuple[int, ...] = ()
    if mode_register is not None:
        mode_register = where.text(mode_register, "classic.mode_register")
        if mode_register not in names:
            raise where.error("classic.mode_register", f"no register named {mode_register!r} in the table")
        modes = raw.get("wheel_modes")
        if not isinstance(modes, list) or not modes:
            raise where.error("classic.wheel_modes", f"a mode_register needs its wheel-mode values, got {modes!r}")
        wheel_modes = tuple(where.integer(v, "classic.wheel_modes") for v in modes)
    elif "wheel_modes" in raw:
        raise where.error("classic.wheel_modes", "belongs to a mode_register")
    gains = {}
    for key, register in (("p_gain_factor", "p_gain"), ("i_gain_factor_s", "i_gain"), ("d_gain_factor_s", "d_gain")):
        if key in raw:
            gains[key] = where.number(raw[key], f"classic.{key}")
            if register not in names:
                raise where.error(f"classic.{key}", f"the table has no {register} register")
    extras: dict[str, Any] = {}
    if "acceleration_unit_deg_s2" in raw:
        extras["acceleration_unit_deg_s2"] = where.number(raw["acceleration_unit_deg_s2"], "classic.acceleration_unit_deg_s2")
        if "goal_acceleration" not in names:
            raise where.error("classic.acceleration_unit_deg_s2", "the table has no goal_acceleration register")
    if ("multi_turn_limit" in raw) != ("multi_turn_goal_limit" in raw):
        raise where.error("classic", "multi_turn_limit and multi_turn_goal_limit come together")
    if "multi_turn_limit" in raw:
        extras["multi_turn_limit"] = where.integer(raw["multi_turn_limit"], "classic.multi_turn_limit")
        extras["multi_turn_goal_limit"] = where.integer(raw["multi_turn_goal_limit"], "classic.multi_turn_goal_limit")
        if extras["multi_turn_goal_limit"] <= 0 or extras["multi_turn_goal_limit"] > 0x7FFF:
            raise where.error("classic.multi_turn_goal_limit", f"must lie in 1..32767 (a 2-byte signed goal), got {extras['multi_turn_goal_limit']}")
    errors_raw = raw.get("errors", {})
    if not isinstance(errors_raw, dict):
        raise where.error("classic.errors", f"must be a table of protection = bit, got {errors_raw!r}")
    errors = []
    for name, value in errors_raw.items():
        where.choice(name, "classic.errors", CLASSIC_ERRORS)
        value = where.integer(value, f"classic.errors.{name}")
        if value <= 0 or value & (value - 1) or value > 0x80:
            raise where.error(f"classic.errors.{name}", f"must be one bit of a byte, got {value}")
        errors.append((name, value))
    return Classic(
        source=where.text(raw["source"], "classic.source"), position_units=units, position_span_deg=span,
        position_centre=centre, speed_unit_rpm=where.number(raw["speed_unit_rpm"], "classic.speed_unit_rpm"),
        direction_bit=bit, output_full_scale=full,
        wheel_output=where.choice(raw.get("wheel_output", "pwm"), "classic.wheel_output", CLASSIC_WHEEL_OUTPUTS),
        mode_register=mode_register, wheel_modes=wheel_modes, errors=tuple(errors), **gains, **extras)


def parse_model(text: str, key: str, path: str) -> ServoModel:
    """A model from the text of its file; ``ValueError`` naming ``path`` and the field on any mistake."""
    where = _Where(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    where.table(data, "top level", {"model", "table", "profiles", "physical", "controller", "mode_change", "classic"},
                {"model", "table", "physical"})
    info = where.table(data["model"], "model", _MODEL_KEYS, {"name", "model_number", "protocols", "source"})
    protocols = info["protocols"]
    if not isinstance(protocols, list) or not protocols:
        raise where.error("model.protocols", f"must be a non-empty list of {PROTOCOLS}, got {protocols!r}")
    for value in protocols:
        where.choice(value, "model.protocols", PROTOCOLS)
    table = where.table(data["table"], "table", _TABLE_KEYS, _TABLE_KEYS)
    table_size = where.integer(table["size"], "table.size")
    if table_size < 1:
        raise where.error("table.size", f"must be positive, got {table_size}")
    entries = _entries(where, table["entries"], "table.entries")
    _check_bounds_names(where, entries, "table.entries")
    seen: dict[str, Entry] = {}
    for entry in entries:
        if entry.name in seen:
            raise where.error("table.entries", f"name {entry.name!r} used twice (addresses {seen[entry.name].address} and {entry.address})")
        seen[entry.name] = entry
    model_number = where.integer(info["model_number"], "model.model_number")
    if "model_number" not in seen or seen["model_number"].default != model_number:
        raise where.error("model.model_number", f"{model_number} must equal the default of the table's model_number entry")
    firmware = info.get("firmware_version")
    if firmware is not None:
        firmware = where.integer(firmware, "model.firmware_version")
    profiles = _profiles(where, data.get("profiles"), key, entries, table_size)
    bauds = _baud_rates(where, info.get("baud_rates_bps"), seen.get("baud_rate"))
    return ServoModel(
        key=key,
        name=where.text(info["name"], "model.name"),
        model_number=model_number,
        firmware_version=firmware,
        protocols=tuple(protocols),
        source=where.text(info["source"], "model.source"),
        table_size=table_size,
        entries=entries,
        profiles=MappingProxyType(profiles),
        physical=_physical(where, data["physical"]),
        path=path,
        baud_rates_bps=bauds,
        controller=_controller(where, data.get("controller")),
        mode_change=_mode_change(where, data.get("mode_change"), seen),
        classic=_classic(where, data.get("classic"), seen),
        unsupported_instructions=_unsupported(where, info.get("unsupported_instructions", []), protocols),
        broadcast_reset_all=where.choice(info.get("broadcast_reset_all", "refused"), "model.broadcast_reset_all",
                                         BROADCAST_RESET_ALL),
    )


def _unsupported(where: _Where, raw: Any, protocols: list[str]) -> frozenset[int]:
    """``model.unsupported_instructions``: Protocol 2.0 instruction names (``Instruction2``'s, in lower case)."""
    if not isinstance(raw, list):
        raise where.error("model.unsupported_instructions", f"must be a list of instruction names, got {raw!r}")
    if raw and "2.0" not in protocols:
        raise where.error("model.unsupported_instructions", "names Protocol 2.0 instructions of a model without it")
    known = {i.name.lower(): int(i) for i in Instruction2 if i not in _ALWAYS_KNOWN}
    codes = []
    for name in raw:
        if name not in known:
            raise where.error("model.unsupported_instructions", f"unknown instruction {name!r}; choose from: "
                              f"{', '.join(known)}")
        codes.append(known[name])
    return frozenset(codes)


def load_model_file(path: str | Path) -> ServoModel:
    """A model from any file (a user's own model, or a test's broken one)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text: {exc}") from None
    return parse_model(text, path.stem, str(path))


def _shipped():
    return resources.files(__package__).joinpath(MODELS_PACKAGE_DIR)


@functools.cache
def model_names() -> tuple[str, ...]:
    """The shipped models' keys, sorted."""
    return tuple(sorted(p.name[: -len(".toml")] for p in _shipped().iterdir() if p.name.endswith(".toml")))


@functools.cache
def model(key: str) -> ServoModel:
    """A shipped model by key ("ax-12a", "xl430-w250", ...)."""
    if key not in model_names():
        raise ValueError(f"unknown servo model {key!r}; choose one of: {', '.join(model_names())}")
    resource = _shipped().joinpath(f"{key}.toml")
    return parse_model(resource.read_text(encoding="utf-8"), key, f"ax12emu/protocol/{MODELS_PACKAGE_DIR}/{key}.toml")
