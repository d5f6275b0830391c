"""Random open-loop excitation: current-reference programs that make the physics show itself.

Segments of 0.4-1.6 s (steps, spins, arcs, creeps, bursts, chirps, coasting), each followed by its mirror
image so the robot wanders little; `ProgramController(program, guard=...)` plays one with an IR guard
(tools/reference_plant/recorder.py).  Used by the agreement check (docs/proving-ground.md).
"""
from __future__ import annotations

import math

import numpy as np

from host_sim.controller.hardware_io import CYCLE_S

KINDS = ("straight", "spin", "arc", "creep", "burst", "chirp", "coast")


def _segment(kind: str, rng: np.random.Generator, n: int) -> np.ndarray:
    t = np.arange(n) * CYCLE_S
    if kind == "straight":
        a = rng.uniform(0.012, 0.035)
        return np.column_stack([np.full(n, a), np.full(n, a)])
    if kind == "spin":
        a = rng.uniform(0.012, 0.03)
        return np.column_stack([np.full(n, -a), np.full(n, a)])
    if kind == "arc":
        a, b = rng.uniform(0.008, 0.035, 2)
        return np.column_stack([np.full(n, a), np.full(n, b)])
    if kind == "creep":  # just above the dry friction's threshold (~9 mA at the nominal robot)
        a = rng.uniform(0.009, 0.014)
        return np.column_stack([np.full(n, a), np.full(n, a * rng.uniform(0.9, 1.1))])
    if kind == "burst":  # a hard start, then coasting
        a = rng.uniform(0.06, 0.2)
        hard = t < rng.uniform(0.08, 0.2)
        return np.column_stack([np.where(hard, a, 0.0), np.where(hard, a, 0.0)])
    if kind == "chirp":
        f0, f1 = 0.3, rng.uniform(2.0, 5.0)
        phase = 2 * math.pi * (f0 * t + (f1 - f0) * t * t / (2 * t[-1] + 1e-9))
        mean, amp, turn = rng.uniform(0.0, 0.015), rng.uniform(0.01, 0.025), rng.uniform(-0.01, 0.01)
        u = mean + amp * np.sin(phase)
        return np.column_stack([u - turn, u + turn])
    return np.zeros((n, 2))  # coast


def program(rng: np.random.Generator, duration: float) -> list[tuple[float, float]]:
    """A random excitation program of `duration` seconds (one row per control period)."""
    rows: list[np.ndarray] = []
    total = int(round(duration / CYCLE_S))
    count = 0
    while count < total:
        kind = KINDS[int(rng.integers(len(KINDS)))]
        n = int(rng.integers(10, 41))
        seg = _segment(kind, rng, n)
        for part in (seg, -seg):
            rows.append(part)
            count += len(part)
    cmd = np.concatenate(rows)[:total]
    return [(float(a), float(b)) for a, b in np.round(cmd, 3)]
