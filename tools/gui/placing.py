"""Where robots may stand: clear of the walls, not under each other, not under a new box.

Pure geometry for tools/gui/app.py and controls.py: the user drags and turns the robots and the
start pose; a box drawn over a robot is refused.  See docs/gui.md.
"""
from __future__ import annotations

import math

import numpy as np

from host_sim.physics.world import World

Pose = tuple[float, float, float]
START_HANDLE = 1.8  # body radii ahead of the start: where its marker's handle is drawn and grabbed


def clear_of_walls(world: World, x: float, y: float, radius: float) -> bool:
    """A body of this radius at (x, y) touches no wall."""
    return not world.n_walls or bool(world.nearest_wall(np.array([[x, y]]))[0][0] >= radius)


def beside(world: World, pose: Pose, radius: float) -> Pose:
    """A pose near `pose`, clear of it and of the walls: left of it, else right, behind, ahead (else itself)."""
    x, y, phi = pose
    for bearing in (math.pi / 2, -math.pi / 2, math.pi, 0.0):
        cx, cy = x + 3 * radius * math.cos(phi + bearing), y + 3 * radius * math.sin(phi + bearing)
        inside = 0 <= cx <= world.size[0] and 0 <= cy <= world.size[1]
        if inside and clear_of_walls(world, cx, cy, radius):
            return (cx, cy, phi)
    return pose


def box_covers(a: tuple[float, float], b: tuple[float, float], x: float, y: float, radius: float) -> bool:
    """The axis-aligned box with corners a and b overlaps a body of this radius at (x, y)."""
    nx = min(max(x, min(a[0], b[0])), max(a[0], b[0]))
    ny = min(max(y, min(a[1], b[1])), max(a[1], b[1]))
    return math.hypot(x - nx, y - ny) < radius


def start_handle(start: Pose, radius: float) -> tuple[float, float]:
    """The start marker's handle: ahead of the start along its heading, free of the robots standing on it."""
    return (start[0] + START_HANDLE * radius * math.cos(start[2]), start[1] + START_HANDLE * radius * math.sin(start[2]))
