"""Exploration measures: how much of the free area the robot has swept (docs/sweep.md).

The free area is the grid of cells (5 cm by default) whose centre a robot centre can reach
from the start without touching a wall.  A cell counts as covered once the robot's centre
has been within one body radius of its centre at a control cycle; `fractions` holds the
covered fraction of the free cells at every control instant.
"""
from __future__ import annotations

import math

import numpy as np

from host_sim.physics.world import World


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
        self.fractions: list[float] = []
        self._count = 0  # covered free cells
        self._last_cell: tuple[int, int] | None = None

    def add(self, x: float, y: float) -> None:
        ny, nx = self.free.shape
        ix = min(max(math.floor(x / self.resolution), 0), nx - 1)
        iy = min(max(math.floor(y / self.resolution), 0), ny - 1)
        if (iy, ix) != self._last_cell:  # the footprint only changes with the cell
            self._last_cell = (iy, ix)
            ys = np.clip(iy + self._dy, 0, ny - 1)
            xs = np.clip(ix + self._dx, 0, nx - 1)
            new = self.free[ys, xs] & ~self.covered[ys, xs]
            if new.any():
                cells = np.unique(ys[new] * nx + xs[new])  # clipping can repeat an edge cell
                self.covered.flat[cells] = True
                self._count += len(cells)
        self.fractions.append(self.fraction)

    @property
    def fraction(self) -> float:
        return self._count / self.n_free if self.n_free else 0.0
