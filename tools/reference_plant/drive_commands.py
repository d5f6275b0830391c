"""Cases for robots of other drives: the plant given an H-bridge, and the firmware's references as that robot's commands.

`with_drive(spec, drive, seed)` makes the robot a voltage, duty or wheel_speed one (its bridge's decay mode drawn
from a stream of its own, into the robot's own winding); `DriveCommands` turns the firmware's current references
into the drive's unit, the command that would push that current through the stalled winding.
docs/proving-ground.md.
"""
from __future__ import annotations

import numpy as np

from host_sim.controller.hardware_io import Actuate, Sense
from host_sim.physics.params import DEFAULT, DRIVES
from tools.reference_plant.robot_model import PlantSpec

BRAKE_SHARE = 0.5  # share of bridge robots whose bridge brakes (slow decay) in its off-phase


def with_drive(spec: PlantSpec, drive: str, seed: int) -> PlantSpec:
    """spec driven by `drive`: unchanged for a current drive; for the others a bridge, whose decay mode is drawn
    (stream [seed, 2024, 9]: the case's effect, world and excitation do not move), into the winding the robot
    already has (PlantSpec.inductance, drawn with the robot: robot_draw.py)."""
    if drive not in DRIVES:
        raise ValueError(f"drive {drive!r} is not one of {', '.join(DRIVES)}")
    if drive == "current":
        return spec
    rng = np.random.default_rng([seed, 2024, 9])
    decay = "brake" if rng.random() < BRAKE_SHARE else "coast"
    return spec.replace(drive=drive, pwm_decay=decay)


def per_amp(drive: str) -> float:
    """The command, in the drive's unit, that pushes one ampere through the datasheet's stalled winding."""
    p = DEFAULT
    volts = p.armature_resistance
    return {"current": 1.0, "voltage": volts, "duty": volts / p.battery_voltage,
            "wheel_speed": volts / (p.torque_constant * p.gear_ratio)}[drive]


class DriveCommands:
    """A current-commanding controller (the firmware, the manoeuvre) as a robot of another drive's: `cycle`
    as the firmware's, and `command` its Actuate in the drive's unit (a duty clipped to [-1, 1])."""

    def __init__(self, inner: object, drive: str) -> None:
        self.inner, self.drive, self.scale = inner, drive, per_amp(drive)
        self.name = getattr(inner, "name", "?")
        self.emitter_pct = getattr(inner, "emitter_pct", 60)

    def cycle(self, s: Sense) -> Actuate:
        return self.inner.cycle(s)  # type: ignore[attr-defined, no-any-return]

    def command(self, a: Actuate) -> tuple[float, float]:
        left, right = a.i_left_ma / 1000.0 * self.scale, a.i_right_ma / 1000.0 * self.scale
        if self.drive == "duty":
            left, right = min(max(left, -1.0), 1.0), min(max(right, -1.0), 1.0)
        return left, right

    def close(self) -> None:
        close = getattr(self.inner, "close", None)
        if close is not None:
            close()
