"""Building the servo model behind a bus from user-facing choices.

Why it exists: the CLI, the Python API and the tests all need "the physical
model at 9.6 V with this parameter file and an arm on each shaft" without
knowing the model classes' constructors; errors come out as ``ValueError``
with a message fit for one line on stderr.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from os import PathLike

from ax12emu.protocol.control_table import AX12_MODEL, DEFAULT_PROFILE, PROTOCOL1_MODELS, Layout, layout
from ax12emu.protocol.servo_models import ServoModel as ServoModelFile
from ax12emu.protocol.servo_models import model as model_file
from firmware_model import KinematicModel, PhysicalModel, ServoParams
from firmware_model.grouped import GroupedModel
from firmware_model.interface import ServoModel

__all__ = ["ModelChoice", "MODELS", "ax_bus_model", "build_model", "build_protocol1_model", "datasheet_params",
           "parse_arm", "shutdown_clears"]

#: Model names accepted by ``--model``.
MODELS = ("physical", "kinematic")


@dataclass(frozen=True)
class ModelChoice:
    """What to put behind the servos."""

    #: "physical" (firmware and physics, the default) or "kinematic" (constant-speed moves).
    name: str = "physical"
    #: A TOML file of ServoParams, effects included (e.g. the params.toml ``firmware_model.diagnose`` writes);
    #: None: the defaults.
    params_path: str | PathLike[str] | None = None
    #: ServoParams as an object (from Python), instead of ``params_path``.
    params: ServoParams | None = None
    #: Supply voltage, V; None: the parameters' (the AX-12A's 9.6 V, on its own bus or beside X-series servos;
    #: another AX model's its model file's recommended supply, see datasheet_params).
    voltage_v: float | None = None
    #: Position controller of the physical model: "compliance" (e-manual) or "pid" (the 2008 report).
    controller: str = "compliance"
    #: Constant external torque on every shaft, N m (positive = CCW).
    external_torque_nm: float = 0.0
    #: An arm on every shaft: (mass kg, length m), gravity acting on it.
    arm: tuple[float, float] | None = None
    #: The AX-12A's control-table profile (``ServoOptions.profile``), the firmware edition whose Alarm Shutdown
    #: the physical model acts out inside a step: "ax12a" (e-manual: Torque Limit 0) or "ax12-2006" (torque off).
    profile: str = DEFAULT_PROFILE


#: The largest arm ``--arm`` takes: far beyond what any of these servos holds (an AX-12A's stall torque is about
#: 1.5 N m; 100 kg at 10 m is 9.8 kN m), yet small enough that the physics stays finite (1e308 overflowed it).
ARM_MASS_MAX_KG, ARM_LENGTH_MAX_M = 100.0, 10.0
#: The largest constant torque on a shaft (N m): the heaviest arm held out level (about 9.8 kN m), far past any
#: servo's stall; more put NaN into the physics (Present Temperature read 0 with no alarm).
EXTERNAL_TORQUE_MAX_NM = ARM_MASS_MAX_KG * 9.80665 * ARM_LENGTH_MAX_M


def parse_arm(text: str) -> tuple[float, float]:
    """"MASS_KG,LENGTH_M" to a pair of non-negative floats."""
    parts = text.split(",")
    if len(parts) != 2:
        raise ValueError(f"expected MASS_KG,LENGTH_M, got {text!r}")
    try:
        mass_kg, length_m = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"expected two numbers MASS_KG,LENGTH_M, got {text!r}") from None
    if not (0 <= mass_kg <= ARM_MASS_MAX_KG and 0 <= length_m <= ARM_LENGTH_MAX_M):
        raise ValueError(f"arm mass must be 0..{ARM_MASS_MAX_KG:g} kg and length 0..{ARM_LENGTH_MAX_M:g} m, got {text!r}")
    return mass_kg, length_m


def shutdown_clears(table: Layout) -> str:
    """The register Alarm Shutdown clears in the firmware edition of ``table`` (its profile's; Torque Limit unless
    it says otherwise), as the physical model takes it (``PhysicalModel(shutdown_clears=)``)."""
    return table.profile.shutdown_clears or "torque_limit"


def build_model(choice: ModelChoice, n: int, clears: str | None = None) -> ServoModel:
    """The model for ``n`` AX-12As, configured as ``choice`` says; ``clears``: the register the servos' Alarm
    Shutdown clears where their tables say it (a bus of AX-18A tables), else ``choice.profile``'s."""
    return _build(choice, n, clears or shutdown_clears(layout(choice.profile)))  # an unknown profile: ValueError


def _build(choice: ModelChoice, n: int, clears: str) -> ServoModel:
    """:func:`build_model` for servos whose Alarm Shutdown clears the register ``clears``."""
    if choice.name not in MODELS:
        raise ValueError(f"unknown model {choice.name!r}; choose one of: {', '.join(MODELS)}")
    if choice.name == "kinematic":
        extras = [flag for flag, used in (
            ("--params", choice.params_path or choice.params), ("--arm", choice.arm), ("--external-torque", choice.external_torque_nm),
            ("--controller pid", choice.controller != "compliance"),
        ) if used]
        if extras:
            raise ValueError(f"{', '.join(extras)} need the physical model (--model physical)")
        # The AX-12A's one default supply, whichever model runs it: the physics' (ServoParams).
        return KinematicModel(n, supply_voltage_v=choice.voltage_v if choice.voltage_v is not None
                              else ServoParams().supply_voltage_v)
    params = _params(choice)
    if choice.arm is not None and params.effects.arm_weight_moment_nm:
        raise ValueError(f"--arm and the parameters' arm (arm_weight_moment_nm = {params.effects.arm_weight_moment_nm:g} "
                         "N m under [effects]) are two arms: give one")
    model = PhysicalModel(n, params, controller=choice.controller, shutdown_clears=clears)
    if choice.voltage_v is not None:
        model.set_supply_voltage(choice.voltage_v)
    if choice.external_torque_nm:
        model.set_external_torque(choice.external_torque_nm)
    if choice.arm is not None:
        model.set_arm(*choice.arm)
    return model


def ax_bus_model(name: str) -> ServoModelFile | None:
    """The model file of a servo the AX bus serves (:data:`PROTOCOL1_MODELS`), by its name as ROBOTIS writes it (a
    Wizard export's model line, a README: "AX-18A"); None for any other name."""
    return next((model_file(key) for key in PROTOCOL1_MODELS if model_file(key).name == name), None)


def datasheet_params(spec: ServoModelFile) -> ServoParams:
    """The physical model's parameters for a Protocol 1.0 model other than the AX-12A, from its data file.

    Why: the AX-12A's defaults are fitted to measurements; another AX model has only its data sheet,
    so its motor comes from the sheet's stall torque, stall current and no-load speed at the rated
    voltage (:meth:`ServoParams.from_datasheet`, friction and, unless the file gives its rotor, inertia scaled
    from the AX-12A's), and it runs at the file's recommended supply (else the rating's voltage) until told
    otherwise.
    """
    physical = spec.physical
    rating = physical.ratings[0]
    low_v, high_v = physical.operating_voltage_v
    params = ServoParams.from_datasheet(
        rating.stall_torque_nm, rating.no_load_speed_rad_s, rating.voltage_v, gear_ratio=physical.gear_ratio,
        min_supply_voltage_v=low_v, max_supply_voltage_v=high_v, stall_current_a=rating.stall_current_a,
        gearbox_efficiency=None if rating.stall_current_a is not None else ServoParams().gearbox_efficiency,
        rotor_inertia_at_motor_kg_m2=physical.rotor_inertia_at_motor_kg_m2)
    supply_v = physical.recommended_voltage_v or rating.voltage_v
    return replace(params, supply_voltage_v=supply_v)


def build_protocol1_model(keys: Sequence[str], choice: ModelChoice = ModelChoice()) -> ServoModel:
    """The model behind Protocol 1.0 servos of these models (one key per servo, in bus order).

    The AX-12A runs ``choice`` as :func:`build_model` does; another model runs its data sheet's
    parameters (:func:`datasheet_params`) with ``choice``'s supply, torque and arm, or, on a wire of that
    model alone, ``choice``'s parameters (a twin the diagnosis fitted to one of its recordings), and its own
    table's Alarm Shutdown (its model file's, as the bus serves it; ``choice.profile`` is the AX-12A's).  Where the
    models differ each group gets its own model, joined by :class:`GroupedModel`; parameters given for such
    a wire are refused, as they do not say whose they are.
    """
    groups: dict[str, list[int]] = {}
    for index, key in enumerate(keys):
        groups.setdefault(key, []).append(index)

    given = choice.params is not None or choice.params_path is not None
    if given and len(groups) > 1:
        raise ValueError(f"servo parameters (--params, params=) on a wire of several models ({', '.join(groups)}): "
                         "they do not say whose they are; serve one model with them")

    def one(key: str, n: int) -> ServoModel:
        if key == AX12_MODEL:
            return build_model(choice, n)
        if choice.name != "physical":
            raise ValueError(f"{key} runs the physical model from its data sheet: --model kinematic applies to the "
                             "AX-12A only")
        spec = model_file(key)
        try:
            return _build(choice if given else replace(choice, params=datasheet_params(spec)), n,
                          shutdown_clears(spec.layout()))
        except ValueError as exc:
            raise ValueError(f"{spec.name}: {exc}") from None

    if len(groups) == 1:
        return one(keys[0], len(keys))
    return GroupedModel([(one(key, len(indices)), indices) for key, indices in groups.items()])


def _params(choice: ModelChoice) -> ServoParams:
    """The choice's parameters: the object, the file (a missing or unreadable one as ValueError) or the defaults."""
    if choice.params is not None and choice.params_path is not None:
        raise ValueError("give servo parameters as a file or as an object, not both")
    if choice.params is not None:
        return choice.params
    if choice.params_path is None:
        return ServoParams()
    try:
        return ServoParams.from_toml(choice.params_path)
    except OSError as exc:
        raise ValueError(f"cannot read the parameter file {str(choice.params_path)!r}: {exc.strerror or exc}") from None
