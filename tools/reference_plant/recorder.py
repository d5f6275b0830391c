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

from host_sim.controller.hardware_io import CYCLE_S, Actuate, Sense
from host_sim.physics.params import DEFAULT
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


def run(plant: Plant, controller: object, duration: float, writer: RecordingWriter | None = None,
        cycle_s: float = CYCLE_S) -> Truth:
    """Drive the plant for `duration` s; returns the truth at each control instant."""
    truth = Truth()
    for _ in range(int(round(duration / cycle_s))):
        pose = plant.true_pose()
        seen = plant.tracker_pose()
        pct = plant.emitter_pct  # the power of this reading's emitter-on sample
        exact = plant.encoder_position()
        s = plant.sense()
        a: Actuate = controller.cycle(s)  # type: ignore[attr-defined]
        plant.actuate(a)
        if writer is not None:
            writer.row(plant.t, (a.i_left_ma / 1000.0, a.i_right_ma / 1000.0), (s.enc_l, s.enc_r), s.adc_on,
                       s.adc_off, s.vbat_mv / 1000.0, seen, emitter_pct=pct)
        truth.poses.append(pose)
        truth.encoders.append(exact)
        plant.advance(cycle_s)
    return truth


def record(path: str | Path, spec: PlantSpec, world: World, controller: object, duration: float, seed: int = 0,
           pose: tuple[float, float, float] | None = None, extra: dict[str, object] | None = None
           ) -> Truth:
    """Run a scenario and write it as a recording; returns the truth (not written)."""
    plant = Plant(spec, world, pose, seed)
    meta = {"plant": "mujoco", "controller": getattr(controller, "name", "?"), "seed": seed,
            "emitter_pct": getattr(controller, "emitter_pct", 60), **(extra or {})}
    with RecordingWriter(path, source="robot", sample_period=CYCLE_S, robot=DEFAULT.to_json(),
                         world=world.to_dict(), extra=meta) as writer:
        truth = run(plant, controller, duration, writer)
    return truth


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi
