"""Exploration measures: how much of the free area the robot has swept.

The free area is the grid of cells (5 cm by default) whose centre a robot
centre can reach from the start without touching a wall.  A cell counts as
covered once the robot's body has been over its centre (centre within one
body radius) at a control cycle.  Coverage is the covered fraction of the
free cells; `time_to(0.9)` is the time to 90 % coverage.
"""
from __future__ import annotations

import math

import numpy as np

from host_sim.world import World


class Coverage:
    def __init__(self, world: World, body_radius: float, resolution: float = 0.05) -> None:
        self.world = world
        self.resolution = resolution
        self.free = world.free_cells(resolution, margin=body_radius, reachable=True)
        self.n_free = int(self.free.sum())
        self.covered = np.zeros_like(self.free)
        r = int(math.ceil(body_radius / resolution))
        dy, dx = np.mgrid[-r:r + 1, -r:r + 1]
        keep = (dx * resolution) ** 2 + (dy * resolution) ** 2 <= body_radius ** 2
        self._dy, self._dx = dy[keep], dx[keep]
        self.times: list[float] = []
        self.fractions: list[float] = []

    def add(self, t: float, x: float, y: float) -> None:
        iy, ix = self.world.cell_of(np.array([x, y]), self.resolution)
        ny, nx = self.free.shape
        ys = np.clip(int(iy) + self._dy, 0, ny - 1)
        xs = np.clip(int(ix) + self._dx, 0, nx - 1)
        self.covered[ys, xs] = True
        self.times.append(t)
        self.fractions.append(self.fraction)

    @property
    def fraction(self) -> float:
        if not self.n_free:
            return 0.0
        return float((self.covered & self.free).sum()) / self.n_free

    def time_to(self, level: float) -> float | None:
        for t, f in zip(self.times, self.fractions):
            if f >= level:
                return t
        return None
