"""The room being edited: walls drawn on a snapping grid, picked, moved, deleted, undone, saved.

Pure state, no drawing: the walls are entries of the world format (docs/worlds.md), so a saved room
is a world file that `twinbot sim --world FILE` reads.  See docs/gui.md.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from host_sim.physics.world import World, WorldError, load_world, save_world, world_from_dict

UNDO_DEPTH = 200


def point_segment_distance(px: float, py: float, seg: list[float]) -> float:
    x1, y1, x2, y2 = seg
    ex, ey = x2 - x1, y2 - y1
    len2 = ex * ex + ey * ey
    u = 0.0 if len2 == 0 else min(1.0, max(0.0, ((px - x1) * ex + (py - y1) * ey) / len2))
    return math.hypot(px - (x1 + u * ex), py - (y1 + u * ey))


def wall_distance(px: float, py: float, wall: dict[str, Any]) -> float:
    """Distance from a point to a wall entry; 0 inside a polygon."""
    if "segment" in wall:
        return point_segment_distance(px, py, wall["segment"])
    pts = wall["polygon"]
    n = len(pts)
    edges = [point_segment_distance(px, py, [*pts[k], *pts[(k + 1) % n]]) for k in range(n)]
    inside = all(_cross(pts[k], pts[(k + 1) % n], (px, py)) >= 0 for k in range(n)) or \
        all(_cross(pts[k], pts[(k + 1) % n], (px, py)) <= 0 for k in range(n))
    return 0.0 if inside else min(edges)


def _cross(a: list[float], b: list[float], p: tuple[float, float]) -> float:
    return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])


def moved_wall(wall: dict[str, Any], dx: float, dy: float) -> dict[str, Any]:
    if "segment" in wall:
        x1, y1, x2, y2 = wall["segment"]
        return {"segment": [x1 + dx, y1 + dy, x2 + dx, y2 + dy]}
    return {"polygon": [[x + dx, y + dy] for x, y in wall["polygon"]]}


class WallEditor:
    """The walls as world-format entries; a loaded file is checked by the same `load_world` as any world file.

    Every change makes a new `World` (its geometry arrays derived once per edit, not per frame) and
    pushes the old walls on the undo stack.
    """

    def __init__(self, world: World, grid: float = 0.05) -> None:
        self.world = world
        self.grid = grid
        self.selected: int | None = None
        self.version = 0  # bumped by every change: caches of the drawn room key on it
        self._undo: list[list[dict[str, Any]]] = []
        self._redo: list[list[dict[str, Any]]] = []  # what undo took back; any new change forgets it
        self._redo_before_move: list[list[dict[str, Any]]] = []

    @property
    def walls(self) -> list[dict[str, Any]]:
        return self.world.walls

    def snap(self, x: float, y: float) -> tuple[float, float]:
        g = self.grid
        return round(round(x / g) * g, 6), round(round(y / g) * g, 6)

    def _change(self, walls: list[dict[str, Any]]) -> None:
        self._undo.append([dict(w) for w in self.world.walls])
        del self._undo[:-UNDO_DEPTH]
        self._redo.clear()
        self._set(walls)

    def _set(self, walls: list[dict[str, Any]]) -> None:
        self.world = self.world.with_changes(walls=walls)
        self.version += 1
        if self.selected is not None and self.selected >= len(walls):
            self.selected = None

    def add_segment(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """A wall from a to b, both snapped to the grid; False (nothing added) if they snap together."""
        a, b = self.snap(*a), self.snap(*b)
        if math.hypot(b[0] - a[0], b[1] - a[1]) < 1e-9:
            return False
        self._change([*self.walls, {"segment": [a[0], a[1], b[0], b[1]]}])
        self.selected = len(self.walls) - 1
        return True

    def add_box(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """A rectangular obstacle (a convex polygon) with corners a and b snapped; False if it has no area."""
        (x0, y0), (x1, y1) = self.snap(*a), self.snap(*b)
        if abs(x1 - x0) < 1e-9 or abs(y1 - y0) < 1e-9:
            return False
        xl, xh, yl, yh = min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1)
        self._change([*self.walls, {"polygon": [[xl, yl], [xh, yl], [xh, yh], [xl, yh]]}])
        self.selected = len(self.walls) - 1
        return True

    def add_polygon(self, corners: list[tuple[float, float]]) -> str | None:
        """A convex obstacle with these (snapped) corners; None if added, else why not (the world format's check)."""
        walls = [*self.walls, {"polygon": [list(self.snap(*c)) for c in corners]}]
        data = self.world.to_dict() | {"walls": walls}
        try:
            world_from_dict(data, "the new polygon")
        except WorldError as exc:
            return str(exc).replace(f"walls[{len(walls) - 1}].polygon: ", "")
        self._change(walls)
        self.selected = len(walls) - 1
        return None

    def pick(self, x: float, y: float, tolerance: float) -> int | None:
        """The wall nearest to (x, y) within tolerance (m), or None."""
        best, best_d = None, tolerance
        for i, wall in enumerate(self.walls):
            d = wall_distance(x, y, wall)
            if d <= best_d:
                best, best_d = i, d
        return best

    def begin_move(self) -> None:
        """Before a drag: one undo step for the whole drag."""
        self._undo.append([dict(w) for w in self.world.walls])
        self._redo_before_move, self._redo = self._redo, []

    def drop_undo(self) -> None:
        """Forget the undo step of a drag that moved nothing."""
        if self._undo:
            self._undo.pop()
        self._redo = self._redo_before_move  # nothing changed: what could be redone still can

    def move_to(self, index: int, original: dict[str, Any], dx: float, dy: float) -> None:
        """Place wall `index` at `original` shifted by (dx, dy) snapped to whole grid steps."""
        g = self.grid
        dx, dy = round(dx / g) * g, round(dy / g) * g
        walls = list(self.walls)
        walls[index] = moved_wall(original, dx, dy)
        self._set(walls)

    def delete(self, index: int | None = None) -> bool:
        index = self.selected if index is None else index
        if index is None or not 0 <= index < len(self.walls):
            return False
        walls = list(self.walls)
        del walls[index]
        self.selected = None
        self._change(walls)
        return True

    def undo(self) -> bool:
        if not self._undo:
            return False
        self.selected = None
        self._redo.append([dict(w) for w in self.world.walls])
        self._set(self._undo.pop())
        return True

    def redo(self) -> bool:
        """Make again the change the last undo took back."""
        if not self._redo:
            return False
        self.selected = None
        self._undo.append([dict(w) for w in self.world.walls])
        self._set(self._redo.pop())
        return True

    def set_start(self, pose: tuple[float, float, float]) -> None:
        """Move the start pose (where a reset puts the robots, saved with the room)."""
        self.world = self.world.with_changes(start=tuple(round(v, 6) for v in pose))
        self.version += 1

    def start_blocked(self, body_radius: float) -> bool:
        """A wall crosses the body of a robot standing at the start."""
        x, y, _phi = self.world.start
        return bool(self.world.nearest_wall(np.array([[x, y]]))[0][0] < body_radius)

    def save(self, path: str | Path) -> None:
        save_world(self.world, path)

    def load(self, path: str | Path, body_radius: float) -> None:
        """Replace the room by a world file (validated; WorldError says what is wrong and where)."""
        world = load_world(path, body_radius)
        self._undo.append([dict(w) for w in self.world.walls])
        self._redo.clear()
        self.world = world
        self.selected = None
        self.version += 1

    def segments_array(self) -> np.ndarray:
        return self.world.segments
