"""Reader for the pendulum logs of Rhoban's BAM ("Better Actuator Models") recorder, raw JSON.

Why it exists: the only real X-series recordings the model can be held to are BAM's XL330 pendulum
logs (``../shared/reference/real-xl330/``, see its README).  They are read here into arrays with
their units in the names, and anything malformed is refused with a ``ValueError`` naming the file
and what is wrong, so a fit never runs on half a file.

Format (BAM ``bam/dynamixel/record.py``, github.com/Rhoban/bam): a JSON object with the set-up
``mass`` (kg, a point mass at the end of the arm), ``length`` (m), optionally ``arm_mass`` or
``arm-mass`` (kg, the arm as a uniform rod; BAM's ``Logs`` takes 0 when absent), ``kp`` (the Position
P Gain register), ``vin`` (V, the supply), ``motor`` and ``trajectory`` names, and ``entries``, one per
sample: ``timestamp`` (s), ``position`` and ``goal_position`` (rad), ``speed`` (rad/s), ``load``,
``input_volts`` (V), ``temp`` (degrees C) and ``torque_enable``.  The recorder writes the goal (and
Torque Enable when it changes), sleeps 1 ms, then reads Present Position, Velocity, PWM, Input
Voltage and Temperature one after the other and stamps the sample at the middle of those reads.
``load`` is Present PWM (0.113 %, 885 = full duty): in these logs the raw register as an unsigned
16-bit number (a negative PWM wraps to 65535 and below); BAM's later recorder writes it as a duty
fraction (``convert_xl330_pwm_to_duty``), read here back into register units.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["PWM_FULL_SCALE", "PendulumLog", "read_bam_log"]

#: Present PWM (124) at full duty (e-manual, X-series "Present PWM": 0.113 % per unit, 885 = 100 %).
PWM_FULL_SCALE = 885

_NUMBERS = ("timestamp", "position", "goal_position", "speed", "load", "input_volts", "temp")


@dataclass(frozen=True)
class PendulumLog:
    """One BAM pendulum log, as arrays (one element per sample)."""

    name: str
    motor: str
    trajectory: str
    #: Position P Gain (84) register value the servo ran with.
    kp: int
    supply_v: float
    mass_kg: float
    length_m: float
    arm_mass_kg: float
    time_s: np.ndarray
    position_rad: np.ndarray
    goal_position_rad: np.ndarray
    speed_rad_s: np.ndarray
    #: Present PWM, signed register units (885 = full duty).
    present_pwm: np.ndarray
    input_voltage_v: np.ndarray
    temperature_c: np.ndarray
    torque_enable: np.ndarray

    @property
    def inertia_kg_m2(self) -> float:
        """The pendulum's inertia about the shaft: the point mass at ``length`` plus the arm as a rod (BAM's Pendulum)."""
        return (self.mass_kg + self.arm_mass_kg / 3.0) * self.length_m**2

    def gravity_moment_nm(self, gravity_m_s2: float) -> float:
        """Largest gravity torque (arm horizontal), ``(m + m_arm / 2) g l`` (BAM's ``Pendulum.compute_bias``)."""
        return (self.mass_kg + self.arm_mass_kg / 2.0) * gravity_m_s2 * self.length_m


#: Bounds of a logged pendulum (as ``ax12emu serve --arm``'s) and of the supply (Present Input Voltage, 0.1 V a unit).
MAX_MASS_KG = 100.0
MAX_LENGTH_M = 10.0
MAX_VIN_V = 25.5


def _number(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    try:
        number = float(value)
    except OverflowError:  # an integer of hundreds of digits
        raise ValueError(f"{where} is too large to be a number") from None
    if not math.isfinite(number):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    return number


def read_bam_log(path: str | Path) -> PendulumLog:
    """Read one BAM JSON log; a file that is not one (bad JSON, missing or non-numeric fields, time not increasing) raises ``ValueError``."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a readable JSON log: {exc}") from exc
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a BAM log is a JSON object, got {type(data).__name__}")
    for key in ("mass", "length", "kp", "vin", "entries"):
        if key not in data:
            raise ValueError(f"{path}: missing {key!r}")
    mass = _number(data["mass"], f"{path}: 'mass'")
    length = _number(data["length"], f"{path}: 'length'")
    arm_mass = _number(data.get("arm_mass", data.get("arm-mass", 0.0)), f"{path}: 'arm_mass'")
    kp = _number(data["kp"], f"{path}: 'kp'")
    vin = _number(data["vin"], f"{path}: 'vin'")
    if mass < 0 or arm_mass < 0 or length <= 0 or vin <= 0 or kp < 0 or kp != int(kp):
        raise ValueError(f"{path}: mass and arm mass must be >= 0, length and vin > 0, kp a register value (>= 0 integer)")
    # What a pendulum on a servo horn can be, and what the registers hold: a length of 1e200 m overflowed.
    if mass > MAX_MASS_KG or arm_mass > MAX_MASS_KG or length > MAX_LENGTH_M or vin > MAX_VIN_V or kp > 16383:
        raise ValueError(f"{path}: mass and arm mass must be at most {MAX_MASS_KG:g} kg, length at most {MAX_LENGTH_M:g} m, "
                         f"vin at most {MAX_VIN_V:g} V and kp a Position P Gain (0..16383)")
    entries = data["entries"]
    if not isinstance(entries, list) or len(entries) < 2:
        raise ValueError(f"{path}: 'entries' must be a list of at least two samples")
    columns: dict[str, list[float]] = {key: [] for key in _NUMBERS}
    enable: list[bool] = []
    for k, entry in enumerate(entries):
        if not isinstance(entry, dict):
            raise ValueError(f"{path}: entry {k} is not an object")
        for key in _NUMBERS:
            if key not in entry:
                raise ValueError(f"{path}: entry {k} has no {key!r}")
            columns[key].append(_number(entry[key], f"{path}: entry {k} {key!r}"))
        te = entry.get("torque_enable")
        if not isinstance(te, (bool, int)) or te not in (0, 1):
            raise ValueError(f"{path}: entry {k} 'torque_enable' must be true/false, got {te!r}")
        enable.append(bool(te))
    time_s = np.asarray(columns["timestamp"])
    if np.any(np.diff(time_s) <= 0):
        k = int(np.argmax(np.diff(time_s) <= 0)) + 1
        raise ValueError(f"{path}: timestamps must increase (entry {k}: {time_s[k]!r} after {time_s[k - 1]!r})")
    load = np.asarray(columns["load"])
    if np.all(load == np.round(load)):
        if np.any((load < 0) | (load > 65535)):
            raise ValueError(f"{path}: 'load' as a register must lie in 0..65535")
        pwm = np.where(load > 32767, load - 65536, load)
    else:  # BAM's later recorder: the duty as a fraction of full scale
        if np.any(np.abs(load) > 1.0):
            raise ValueError(f"{path}: a fractional 'load' is a duty and must lie in -1..1")
        pwm = np.round(load * PWM_FULL_SCALE)
    if np.any(np.abs(pwm) > PWM_FULL_SCALE):
        raise ValueError(f"{path}: Present PWM beyond full scale ({PWM_FULL_SCALE}): {pwm[np.abs(pwm) > PWM_FULL_SCALE][0]:g}")
    return PendulumLog(
        name=path.stem,
        motor=str(data.get("motor", "")),
        trajectory=str(data.get("trajectory", "")),
        kp=int(kp),
        supply_v=vin,
        mass_kg=mass,
        length_m=length,
        arm_mass_kg=arm_mass,
        time_s=time_s,
        position_rad=np.asarray(columns["position"]),
        goal_position_rad=np.asarray(columns["goal_position"]),
        speed_rad_s=np.asarray(columns["speed"]),
        present_pwm=pwm.astype(np.int64),
        input_voltage_v=np.asarray(columns["input_volts"]),
        temperature_c=np.asarray(columns["temp"]),
        torque_enable=np.asarray(enable, dtype=bool),
    )
