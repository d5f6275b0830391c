"""Cases for robots of other drives: the plant given an H-bridge, and the firmware's references as that robot's commands.

`with_drive(spec, drive, seed)` makes the robot a voltage, duty or wheel_speed one (its bridge's decay mode and
winding drawn from a stream of their own); `DriveCommands` turns the firmware's current references into the
drive's unit, the command that would push that current through the stalled winding.  docs/proving-ground.md.
"""
from __future__ import annotations

import numpy as np

from host_sim.controller.hardware_io import Actuate, Sense
from host_sim.physics.params import DEFAULT, DRIVES
from tools.reference_plant.robot_model import PlantSpec

INDUCTANCE_SPREAD = 0.1  # relative sd of the winding's inductance about the datasheet's
BRAKE_SHARE = 0.5  # share of bridge robots whose bridge brakes (slow decay) in its off-phase


def with_drive(spec: PlantSpec, drive: str, seed: int) -> PlantSpec:
    """spec driven by `drive`: unchanged for a current drive; a bridge's decay mode and its winding's inductance
    drawn for the others (stream [seed, 2024, 9]: the case's effect, world and excitation do not move)."""
    if drive not in DRIVES:
        raise ValueError(f"drive {drive!r} is not one of {', '.join(DRIVES)}")
    if drive == "current":
        return spec
    rng = np.random.default_rng([seed, 2024, 9])
    decay = "brake" if rng.random() < BRAKE_SHARE else "coast"
    henry = tuple(float(h) * (1.0 + INDUCTANCE_SPREAD * float(np.clip(rng.standard_normal(), -3, 3)))
                  for h in spec.bridge_inductance)
    return spec.replace(drive=drive, pwm_decay=decay, bridge_inductance=henry)


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
