"""Servos of different models on one bus: one model per group of servos, seen as one model of N.

Why it exists: the physical model runs one parameter set for all its servos (its constants are
folded into the stepping kernels), while one Protocol 1.0 wire may carry AX-12As beside AX-18As,
each with its own motor.  Rather than per-servo parameter arrays through every kernel, each group
keeps its own model and this one splits the commands by servo index and joins the sensors, so the
bus, its plant and the faults see one model of N servos.  All groups step on one grid (the same
step), so they stay at one time.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import fields

import numpy as np

from .interface import AngleSettable, Blockable, Commands, Sensed, ServoModel, SteppableTo

__all__ = ["GroupedModel"]


class GroupedModel:
    """N servos, each group of indices behind its own model; implements :class:`ServoModel`."""

    def __init__(self, groups: Sequence[tuple[ServoModel, Sequence[int]]]) -> None:
        if not groups:
            raise ValueError("need at least one group of servos")
        indices = [np.asarray(list(group), dtype=np.intp) for _, group in groups]
        n = sum(len(group) for group in indices)
        if sorted(np.concatenate(indices).tolist()) != list(range(n)):
            raise ValueError(f"the groups must hold each servo index 0..{n - 1} once, got {[g.tolist() for g in indices]}")
        for (model, _), group in zip(groups, indices):
            if model.n != len(group):
                raise ValueError(f"a model of {model.n} servos given {len(group)} indices")
        first = groups[0][0]
        if any(model.step_s != first.step_s or model.time_s != first.time_s for model, _ in groups):
            raise ValueError("the groups' models must share one step and one present time")
        self.n = n
        self.step_s = first.step_s
        self._models = [model for model, _ in groups]
        self._indices = indices
        #: Where each servo is: (group, index inside the group's model).
        self._where = {int(i): (g, k) for g, group in enumerate(indices) for k, i in enumerate(group.tolist())}

    @property
    def models(self) -> list[ServoModel]:
        """The groups' models, in the order given."""
        return list(self._models)

    @property
    def time_s(self) -> float:
        return self._models[0].time_s

    # -- the seam ----------------------------------------------------------------------
    def _split(self, commands: Commands) -> list[Commands]:
        names = Commands.field_names()
        return [Commands(**{name: np.asarray(getattr(commands, name))[group] for name in names})
                for group in self._indices]

    def _join(self, parts: list[Sensed]) -> Sensed:
        joined = {}
        for field in fields(Sensed):
            arrays = [np.asarray(getattr(part, field.name)) for part in parts]
            out = np.empty(self.n, dtype=np.result_type(*arrays))
            for group, array in zip(self._indices, arrays):
                out[group] = array
            out.flags.writeable = False
            joined[field.name] = out
        return Sensed(**joined)

    def step_to(self, to_time_s: float, commands: Commands) -> None:
        for model, part in zip(self._models, self._split(commands)):
            if isinstance(model, SteppableTo):
                model.step_to(to_time_s, part)
            else:
                model.advance(to_time_s, part)

    def advance(self, to_time_s: float, commands: Commands) -> Sensed:
        return self._join([model.advance(to_time_s, part) for model, part in zip(self._models, self._split(commands))])

    def sense(self) -> Sensed:
        return self._join([model.sense() for model in self._models])

    # -- run-time inputs, per servo or for all -----------------------------------------
    def _per_servo(self, values, dtype) -> list[np.ndarray]:
        array = np.broadcast_to(np.asarray(values, dtype=dtype), (self.n,))
        return [array[group] for group in self._indices]

    def set_external_torque(self, torque_nm) -> None:
        for model, part in zip(self._models, self._per_servo(torque_nm, float)):
            model.set_external_torque(part)

    @property
    def external_torque_nm(self) -> np.ndarray:
        """Each servo's external torque, gathered from its group's model."""
        torques = np.zeros(self.n)
        for model, group in zip(self._models, self._indices):
            torques[group] = model.external_torque_nm
        return torques

    def set_supply_voltage(self, volts: float) -> None:
        """One supply for the wire; each group checks it against its own valid range."""
        for model in self._models:
            model.set_supply_voltage(volts)  # type: ignore[attr-defined]

    def set_arm(self, mass_kg, length_m) -> None:
        masses, lengths = self._per_servo(mass_kg, float), self._per_servo(length_m, float)
        for model, mass, length in zip(self._models, masses, lengths):
            model.set_arm(mass, length)  # type: ignore[attr-defined]

    def set_blocked(self, blocked) -> None:
        for model, part in zip(self._models, self._per_servo(blocked, bool)):
            if not isinstance(model, Blockable):
                raise TypeError(f"{type(model).__name__} cannot hold its shafts")
            model.set_blocked(part)

    def set_angle(self, index: int, angle_rad: float) -> None:
        group, local = self._where[int(index)]
        model = self._models[group]
        if not isinstance(model, AngleSettable):
            raise TypeError(f"{type(model).__name__} cannot set a shaft's angle")
        model.set_angle(local, angle_rad)

    @property
    def angle_rad(self) -> np.ndarray:
        """Output shaft angles, radians, in servo order."""
        out = np.empty(self.n)
        for model, group in zip(self._models, self._indices):
            out[group] = model.angle_rad  # type: ignore[attr-defined]
        return out
