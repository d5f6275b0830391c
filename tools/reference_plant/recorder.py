"""Scenarios on the plant, written as recordings in the project's one format.

    run(plant, controller, duration, writer)      # one control period at a time -> Truth
    record(path, spec, world, controller, ...)    # a recording (source "robot", plant "mujoco") -> Truth

The sidecar holds the twin's nominal robot, never the plant's true values; `Truth` (the true pose and the
encoders' unrounded positions) is returned for an answer key.  docs/proving-ground.md.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from host_sim.controller.hardware_io import CYCLE_S, Actuate, Sense
from host_sim.physics.params import DEFAULT, DRIVE_UNITS
from host_sim.recordings.recording import RecordingWriter
from host_sim.physics.world import World
from tools.reference_plant.plant import Plant
from tools.reference_plant.robot_model import PlantSpec



@dataclass
class Truth:
    """What the plant knows and a recording does not, one entry per control instant (row)."""

    poses: list[tuple[float, float, float]] = field(default_factory=list)  # C's true pose
    encoders: list[tuple[float, float]] = field(default_factory=list)  # ticks, not rounded (the readings' floor)


class ProgramController:
    """Given current references (A), one pair per control period, open loop; zero after the end.

    guard: counts of reflected light (on - off) on any front sensor (S8, S1,
    S2) above which the program pauses with zero current until the wall is
    out of sight again (keeps open-loop excitation off the walls); None = no guard.
    """

    name = "program"

    def __init__(self, currents: Sequence[tuple[float, float]], emitter_pct: int = 60,
                 guard: float | None = None) -> None:
        self.currents = list(currents)
        self.k = 0
        self.emitter_pct = emitter_pct
        self.guard = guard

    def cycle(self, s: Sense) -> Actuate:
        left, right = self.currents[self.k] if self.k < len(self.currents) else (0.0, 0.0)
        self.k += 1
        if self.guard is not None and s.adc_on:
            seen = max(s.adc_on[i] - s.adc_off[i] for i in (7, 0, 1, 3, 4, 5))
            front = left + right > 0
            near_front = max(s.adc_on[i] - s.adc_off[i] for i in (7, 0, 1)) > self.guard
            near_back = max(s.adc_on[i] - s.adc_off[i] for i in (3, 4, 5)) > self.guard
            if seen > self.guard and ((front and near_front) or (not front and near_back)):
                left = right = 0.0
        return Actuate(round(left * 1000), round(right * 1000), self.emitter_pct)

    def close(self) -> None:
        pass


LATE_MS = (5, 15)  # a late period overruns by this many ms (a busy link, a garbage collection)
MIN_PERIOD_MS = 30  # the firmware's period never shortens below this


def next_period(plant: Plant, rng: np.random.Generator, cycle_s: float) -> float:
    """The firmware's next period, in whole plant steps: the nominal one, jittered (period_jitter), sometimes
    late (late_share)."""
    s = plant.spec
    steps = cycle_s / plant.dt
    if s.period_jitter > 0:
        steps += s.period_jitter / plant.dt * float(rng.standard_normal())
    if s.late_share > 0 and rng.random() < s.late_share:
        steps += float(rng.integers(LATE_MS[0], LATE_MS[1] + 1)) * 0.001 / plant.dt
    return max(round(steps), round(MIN_PERIOD_MS * 0.001 / plant.dt)) * plant.dt


def run(plant: Plant, controller: object, duration: float, writer: RecordingWriter | None = None,
        cycle_s: float = CYCLE_S, seed: int = 0) -> Truth:
    """Drive the plant for `duration` s, a row per firmware period at its true time (jittered; rows the link
    loses, drop_share, are not written); returns the truth at each written row."""
    truth = Truth()
    timing = np.random.default_rng([seed, 3])  # the firmware's and the link's timing: a stream of its own
    while plant.t < duration - 1e-9:
        pose = plant.true_pose()
        seen = plant.tracker_pose()
        pct = plant.emitter_pct  # the power of this reading's emitter-on sample
        exact = plant.encoder_position()
        s = plant.sense()
        a: Actuate = controller.cycle(s)  # type: ignore[attr-defined]
        # a controller of another drive says its command in that drive's unit (drive_commands.py)
        to_drive = getattr(controller, "command", None)
        cmd = to_drive(a) if to_drive is not None else (a.i_left_ma / 1000.0, a.i_right_ma / 1000.0)
        plant.command(cmd, a.emitter_pct)
        lost = plant.spec.drop_share > 0 and timing.random() < plant.spec.drop_share
        if writer is not None and not lost:
            writer.row(plant.t, cmd, (s.enc_l, s.enc_r), s.adc_on,
                       s.adc_off, s.vbat_mv / 1000.0, seen, emitter_pct=pct)
        if not lost:
            truth.poses.append(pose)
            truth.encoders.append(exact)
        plant.advance(next_period(plant, timing, cycle_s))
    return truth


def record(path: str | Path, spec: PlantSpec, world: World, controller: object, duration: float, seed: int = 0,
           pose: tuple[float, float, float] | None = None, extra: dict[str, object] | None = None
           ) -> Truth:
    """Run a scenario and write it as a recording; returns the truth (not written).  The commands are in the
    drive's unit; the sidecar's robot and its drive block say which (docs/recordings.md "The drive")."""
    plant = Plant(spec, world, pose, seed)
    meta = {"plant": "mujoco", "controller": getattr(controller, "name", "?"), "seed": seed,
            "emitter_pct": getattr(controller, "emitter_pct", 60), **(extra or {})}
    robot = DEFAULT.to_json()
    if spec.drive != "current":  # the robot's design, known as its datasheet is: its drive and its bridge's decay
        robot.update(drive=spec.drive, pwm_decay=spec.pwm_decay)
        unit = DRIVE_UNITS[spec.drive]
        meta["drive"] = {"kind": spec.drive, "unit": unit, "source_unit": unit,
                         "full_scale": 1.0 if spec.drive == "duty" else None}
    with RecordingWriter(path, source="robot", sample_period=CYCLE_S, robot=robot,
                         world=world.to_dict(), extra=meta) as writer:
        truth = run(plant, controller, duration, writer, seed=seed)
    return truth


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi
