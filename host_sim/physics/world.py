"""Worlds: walls (segments and convex polygons), lamps, and the geometry on them.

A world is a JSON file (`load_world`, `builtin_world`, `world_by_name_or_path`; errors name the file
and the entry).  `World` casts rays (`ray_cast`, `cast_robots` for the IR ring), finds the nearest and
every wall (`nearest_wall`, `wall_distances`, for contact), tests lines of sight (lamps) and builds
the coverage grid (`free_cells`).  Format and conventions: docs/worlds.md.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike

from host_sim.physics.params import DEFAULT, read_json

WORLDS_DIR = Path(__file__).resolve().parents[1] / "worlds"
BUILTIN_NAMES = ("paper_room", "maze", "arena")
TOP_KEYS = {"name", "description", "size", "walls", "start", "lamps", "ambient"}
LAMP_KEYS = {"x", "y", "level", "flicker_hz", "flicker_depth"}
DEFAULT_FLICKER_DEPTH = 0.3  # fraction of the lamp's level, when flicker_hz is given
DEFAULT_BODY_RADIUS = DEFAULT.body_radius  # m, for the start check and the free cells
_EPS = 1e-9  # m, geometric tolerance
# Bounds that keep a world's set-up and runs to seconds and megabytes.  The
# coverage grid (host_sim/loops/coverage.py, cells of GRID_RESOLUTION) and the
# free-cell map measure every cell's distance to every wall segment.
GRID_RESOLUTION = 0.05  # m, the coverage grid's default cell
MAX_SIZE_M = 50.0  # m per side: 1000 x 1000 coverage cells
MAX_GRID_CELLS = 1_000_000
MAX_SEGMENTS = 5_000  # wall segments, polygon edges included
MAX_GRID_WORK = 20_000_000  # coverage cells x wall segments: about 2 s of set-up
MAX_COORD_M = 1_000.0  # |x|, |y| of any wall, lamp or start point
MAX_LAMP_LEVEL = 1e6  # counts at 1 m; an ADC saturates at 4095 (12 bits)
MAX_FLICKER_HZ = 1e4


class WorldError(ValueError):
    """A world file is wrong; the message names the file, the entry and the problem."""


@dataclass(frozen=True)
class Lamp:
    x: float
    y: float
    level: float  # ADC counts at 1 m, straight along the sensor axis
    flicker_hz: float = 0.0  # 0 = steady
    flicker_depth: float = DEFAULT_FLICKER_DEPTH  # level * (1 + depth * sin(2 pi f t))

    def level_at(self, t: float | np.ndarray) -> float | np.ndarray:
        if not self.flicker_hz:
            return self.level
        return self.level * (1.0 + self.flicker_depth * np.sin(2.0 * np.pi * self.flicker_hz * np.asarray(t)))

    def to_dict(self) -> dict[str, float]:
        d = {"x": self.x, "y": self.y, "level": self.level}
        if self.flicker_hz:
            d["flicker_hz"] = self.flicker_hz
            d["flicker_depth"] = self.flicker_depth
        return d


@dataclass(eq=False)
class World:
    """Walls, start pose and light sources; geometry arrays built once."""

    name: str
    size: tuple[float, float]
    walls: list[dict[str, Any]]  # as in the file: {"segment": [...]} or {"polygon": [[x, y], ...]}
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lamps: tuple[Lamp, ...] = ()
    ambient: float | None = None  # counts; None = the robot parameters' ir_ambient
    description: str = ""
    source: str = "<memory>"
    # Derived, filled by __post_init__.
    segments: np.ndarray = field(init=False, repr=False)  # (M, 4) x1, y1, x2, y2
    segment_entry: np.ndarray = field(init=False, repr=False)  # (M,) index into walls
    lamp_xy: np.ndarray = field(init=False, repr=False)  # (L, 2)
    flickers: bool = field(init=False, repr=False)  # some lamp flickers
    polygons: list[np.ndarray] = field(init=False, repr=False)  # counter-clockwise (K, 2) vertices

    def __post_init__(self) -> None:
        segs: list[list[float]] = []
        entry: list[int] = []
        self.polygons = []
        self._poly_entry: list[int] = []
        for i, wall in enumerate(self.walls):
            if "segment" in wall:
                segs.append([float(v) for v in wall["segment"]])
                entry.append(i)
            else:
                pts = np.asarray(wall["polygon"], dtype=float)
                if _signed_area(pts) < 0:
                    pts = pts[::-1]
                self.polygons.append(pts)
                self._poly_entry.append(i)
                for k in range(len(pts)):
                    a, b = pts[k], pts[(k + 1) % len(pts)]
                    segs.append([a[0], a[1], b[0], b[1]])
                    entry.append(i)
        self.segments = np.asarray(segs, dtype=float).reshape(-1, 4)
        self.segment_entry = np.asarray(entry, dtype=int)
        self.lamp_xy = np.array([[lamp.x, lamp.y] for lamp in self.lamps], dtype=float).reshape(-1, 2)
        self._lamp_level = np.array([lamp.level for lamp in self.lamps], dtype=float)
        self._lamp_omega = np.array([2 * math.pi * lamp.flicker_hz for lamp in self.lamps], dtype=float)
        self._lamp_depth = np.array([lamp.flicker_depth if lamp.flicker_hz else 0.0 for lamp in self.lamps])
        self.flickers = bool(self._lamp_depth.any())
        self._prepare()

    # ------------------------------------------------------------------ set-up
    def _prepare(self) -> None:
        s = self.segments
        m = len(s)
        a = s[:, :2]
        e = s[:, 2:] - s[:, :2]
        self._a = a
        self._e = e
        self._len2 = np.maximum((e * e).sum(1), _EPS * _EPS)
        normal = np.stack([e[:, 1], -e[:, 0]], 1) / np.sqrt(self._len2)[:, None]
        self._normal = normal  # unit, right of a->b (outward for counter-clockwise polygons)
        # Ray o + t d against segment a + s e (docs/worlds.md, "How the ray cast works"):
        # features f = [dx, dy, ox, oy, 1, ox*dy - oy*dx]; f @ W gives, per wall,
        # den = d x e, tnum = t*den, unum = (s - 1/2)*den and dot = d . e.
        w = np.zeros((6, 4, m))
        ex, ey, ax, ay = e[:, 0], e[:, 1], a[:, 0], a[:, 1]
        w[0, 0], w[1, 0] = ey, -ex  # den
        w[2, 1], w[3, 1], w[4, 1] = -ey, ex, ax * ey - ay * ex  # tnum
        w[0, 2], w[1, 2], w[5, 2] = -ay - 0.5 * ey, ax + 0.5 * ex, -1.0  # unum
        w[0, 3], w[1, 3] = ex, ey  # dot
        self._w = w.reshape(6, 4 * m)
        self._robot_kernels: dict[tuple[object, ...], np.ndarray] = {}
        self._offsets: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._ws: dict[int, dict[str, np.ndarray]] = {}
        self._visibility: dict[tuple[float, ...], Any] = {}
        self._lamp_vis: Any = None
        # Half-planes of the convex obstacles: n . p <= c inside, one row per edge.
        rows: list[np.ndarray] = []
        cs: list[float] = []
        starts: list[int] = []
        for pts in self.polygons:
            starts.append(len(rows))
            for k in range(len(pts)):
                p0, p1 = pts[k], pts[(k + 1) % len(pts)]
                ed = p1 - p0
                n = np.array([ed[1], -ed[0]]) / math.hypot(*ed)
                rows.append(n)
                cs.append(float(n @ p0))
        self._hp_n = np.asarray(rows, dtype=float).reshape(-1, 2)
        self._hp_c = np.asarray(cs, dtype=float)
        self._hp_starts = np.asarray(starts, dtype=int)
        # For every segment, the convex obstacle it bounds (-1: a free-standing wall).
        poly_of_entry = {entry: k for k, entry in enumerate(self._poly_entry)}
        self._seg_polygon = np.array([poly_of_entry.get(int(e), -1) for e in self.segment_entry], dtype=int)

    # ------------------------------------------------------------------ basics
    def lamp_levels(self, t: ArrayLike = 0.0) -> np.ndarray:
        """Every lamp's level (counts at 1 m) at time t (s): shape t.shape + (n_lamps,)."""
        if not self.flickers:
            if isinstance(t, (int, float)):
                return self._lamp_level
            return np.broadcast_to(self._lamp_level, np.shape(t) + self._lamp_level.shape)
        t = np.asarray(t, dtype=float)[..., None]
        return self._lamp_level * (1.0 + self._lamp_depth * np.sin(self._lamp_omega * t))

    @property
    def n_walls(self) -> int:
        """Number of wall segments, polygon edges included."""
        return len(self.segments)

    @property
    def width(self) -> float:
        return self.size[0]

    @property
    def height(self) -> float:
        return self.size[1]

    def outside(self, points: np.ndarray) -> np.ndarray:
        """True where a point lies outside the area of interest [0, w] x [0, h]."""
        p = np.asarray(points, dtype=float)
        return (p[..., 0] < 0) | (p[..., 0] > self.size[0]) | (p[..., 1] < 0) | (p[..., 1] > self.size[1])

    def to_dict(self) -> dict[str, Any]:
        """The world as its JSON file holds it (save with `save_world`)."""
        d: dict[str, Any] = {"name": self.name}
        if self.description:
            d["description"] = self.description
        d["size"] = list(self.size)
        d["walls"] = [dict(w) for w in self.walls]
        d["start"] = {"x": self.start[0], "y": self.start[1], "phi": self.start[2]}
        if self.lamps:
            d["lamps"] = [lamp.to_dict() for lamp in self.lamps]
        if self.ambient is not None:
            d["ambient"] = self.ambient
        return d

    def with_changes(self, **changes: Any) -> World:
        """A copy with some of name, size, walls, start, lamps, ambient replaced."""
        d: dict[str, Any] = {"name": self.name, "size": self.size, "walls": self.walls, "start": self.start,
             "lamps": self.lamps, "ambient": self.ambient, "description": self.description, "source": self.source}
        d.update(changes)
        return World(**d)

    # ------------------------------------------------------------------ rays
    def ray_cast(self, origins: np.ndarray, directions: np.ndarray,
                 max_range: float = math.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cast rays o + t d (t >= 0) and return the nearest wall hit of each.

        origins (..., 2) and directions (..., 2) broadcast together; directions
        must be unit vectors (distance is then in metres).  Returns arrays of
        the broadcast batch shape:

        distance   metres to the hit point; inf where nothing is hit within
                   max_range;
        incidence  signed angle (rad, in [-pi/2, pi/2]) between the wall's
                   normal and the ray: atan((d . e) / (d x e)) with e the wall's
                   direction; 0 along the normal, +-pi/2 grazing; its sign says
                   on which side the wall recedes (the sensor model uses |angle|);
                   0 where nothing is hit;
        hit        True where a wall was hit within max_range.

        A ray parallel to a wall never hits it; a ray through a wall's end
        point does.
        """
        o = np.asarray(origins, dtype=float)
        d = np.asarray(directions, dtype=float)
        shape = np.broadcast_shapes(o.shape, d.shape)
        o = np.broadcast_to(o, shape).reshape(-1, 2)
        d = np.broadcast_to(d, shape).reshape(-1, 2)
        f = np.empty((len(o), 6))
        f[:, 0:2] = d
        f[:, 2:4] = o
        f[:, 4] = 1.0
        f[:, 5] = o[:, 0] * d[:, 1] - o[:, 1] * d[:, 0]
        dist, inc, hit = self._solve(self._terms(f, self._w, len(o)), len(o), max_range)
        return dist.reshape(shape[:-1]), inc.reshape(shape[:-1]), hit.reshape(shape[:-1])

    _BIG = 4096  # ray-wall pairs above which _solve works in preallocated buffers

    def _workspace(self, n_rays: int) -> dict[str, np.ndarray]:
        """Buffers for a batch of n_rays rays, kept between calls.

        Large temporaries are otherwise mapped and unmapped by the C library
        on every call, and the page faults cost more than the arithmetic
        (2 to 3 times the time of a 1000-robot cast).
        """
        ws = self._ws.get(n_rays)
        if ws is None:
            if len(self._ws) > 8:
                self._ws.clear()
            m = len(self.segments)
            ws = self._ws[n_rays] = {
                "terms": np.empty((4, n_rays, m)), "r": np.empty((2, n_rays, m)), "key": np.empty((n_rays, m)),
                "valid": np.empty((n_rays, m), dtype=bool), "tmp": np.empty((n_rays, m), dtype=bool)}
        return ws

    def _solve(self, prod: np.ndarray, n_rays: int, max_range: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest valid hit of each ray from the ray terms prod, laid out (4, n_rays, M) contiguous:

        den = d x e, tnum = t den, unum = (s - 1/2) den, dot = d . e.
        """
        m = len(self.segments)
        if m == 0:
            return np.full(n_rays, np.inf), np.zeros(n_rays), np.zeros(n_rays, dtype=bool)
        p = prod.reshape(4, n_rays, m)
        if n_rays * m <= self._BIG:
            with np.errstate(divide="ignore", invalid="ignore"):
                r = p[1:3] / p[0]  # t and (s - 1/2); nan or inf for parallel walls
            t = r[0]
            valid = np.abs(r[1]) <= 0.5
            valid &= t >= 0.0
            key = np.where(valid, t, np.inf)
        else:  # the same in place
            ws = self._workspace(n_rays)
            r, key, valid, tmp = ws["r"], ws["key"], ws["valid"], ws["tmp"]
            with np.errstate(divide="ignore", invalid="ignore"):
                np.divide(p[1:3], p[0], out=r)
            t = r[0]
            np.less_equal(np.abs(r[1], out=key), 0.5, out=valid)
            valid &= np.greater_equal(t, 0.0, out=tmp)
            key.fill(np.inf)
            np.copyto(key, t, where=valid)
        idx = key.argmin(1)
        offsets = self._offsets.get(n_rays)
        if offsets is None:
            if len(self._offsets) > 8:
                self._offsets.clear()
            rows = np.arange(n_rays) * m
            offsets = self._offsets[n_rays] = (rows, np.stack([rows + 3 * n_rays * m, rows]))
        dist = key.ravel()[offsets[0] + idx]
        hit = dist <= min(max_range, 1e300)  # inf (no hit) is never within range
        dot, den = prod.ravel()[offsets[1] + idx]  # d . e and d x e of the wall hit
        inc = np.arctan(dot / np.where(hit, den, 1.0))
        return np.where(hit, dist, np.inf), np.where(hit, inc, 0.0), hit

    def _terms(self, feats: np.ndarray, matrix: np.ndarray, n_rays: int) -> np.ndarray:
        """feats (B, F) @ matrix (F, 4 * B'), laid out block-major (4, n_rays, M) for _solve."""
        m = len(self.segments)
        blocks = matrix.reshape(len(matrix), 4, -1)
        if n_rays * m <= self._BIG:
            return np.ascontiguousarray((feats @ matrix).reshape(len(feats), 4, -1).transpose(1, 0, 2))
        terms = self._workspace(n_rays)["terms"].reshape(4, len(feats), -1)
        for b in range(4):
            np.matmul(feats, blocks[:, b], out=terms[b])
        return terms

    def robot_kernel(self, bearings: Sequence[float],
                     origins: Sequence[tuple[float, float]] | None = None) -> np.ndarray:
        """(9, 4*R*M) matrix turning a pose into the ray terms of R fixed-bearing rays.

        Ray k leaves the centre (x, y) - or, with origins, the point
        origins[k] = (forward, left) (m) from it in the robot's frame - in
        direction phi + bearing[k].  Its features f are linear in h = [cos,
        sin, x cos, x sin, y cos, y sin, x, y, 1] (of phi), so f @ W = h @ K
        with K = G @ W computed once.
        """
        # The sensor model passes tuples: used as they are, no key is built per call.
        key = (bearings if type(bearings) is tuple else tuple(float(b) for b in bearings),
               origins if origins is None or type(origins) is tuple else tuple(map(tuple, origins)))
        kern = self._robot_kernels.get(key)
        if kern is None:
            b = np.asarray(key[0])
            bx, by = np.cos(b), np.sin(b)
            n = len(b)
            g = np.zeros((n, 6, 9))
            # dx = c bx - s by ; dy = s bx + c by
            g[:, 0, 0], g[:, 0, 1] = bx, -by
            g[:, 1, 0], g[:, 1, 1] = by, bx
            g[:, 2, 6] = 1.0  # ox = x (+ c fx - s fy)
            g[:, 3, 7] = 1.0  # oy = y (+ s fx + c fy)
            g[:, 4, 8] = 1.0
            # x dy - y dx = x c by + x s bx - y c bx + y s by
            g[:, 5, 2], g[:, 5, 3], g[:, 5, 4], g[:, 5, 5] = by, bx, -bx, by
            if origins is not None:  # the offset turns with the robot; o x d gains f x (bx, by), the same at any phi
                fx, fy = np.asarray(key[1], dtype=float).reshape(n, 2).T
                g[:, 2, 0], g[:, 2, 1] = fx, -fy
                g[:, 3, 0], g[:, 3, 1] = fy, fx
                g[:, 5, 8] = fx * by - fy * bx
            # K[k, block, ray, wall]: the terms come out block-major, as _solve wants them.
            kern = np.einsum("njk,jbm->kbnm", g, self._w.reshape(6, 4, -1)).reshape(9, -1)
            self._robot_kernels[key] = kern
        return kern

    def cast_robots(self, poses: np.ndarray, bearings: Sequence[float], max_range: float = math.inf,
                    origins: Sequence[tuple[float, float]] | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rays from robot centres at fixed bearings: poses (..., 3) -> arrays (..., R).

        Same results as ray_cast from (x, y) along phi + bearing, faster: one
        matrix product does the whole front end.  origins: per ray, where it
        starts in the robot's frame, (forward, left) m from the centre
        (default the centre); the distance is then from that point.
        """
        q = np.asarray(poses, dtype=float)
        batch = q.shape[:-1]
        q = q.reshape(-1, 3)
        n_rob = len(q)
        c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
        x, y = q[:, 0], q[:, 1]
        h = np.stack([c, s, x * c, x * s, y * c, y * s, x, y, np.ones(n_rob)], 1)
        n = len(bearings)
        kern = self.robot_kernel(bearings, origins)
        dist, inc, hit = self._solve(self._terms(h, kern, n_rob * n), n_rob * n, max_range)
        return dist.reshape(batch + (n,)), inc.reshape(batch + (n,)), hit.reshape(batch + (n,))

    def cast_robot(self, x: float, y: float, phi: float, bearings: Sequence[float], max_range: float = math.inf,
                   origins: Sequence[tuple[float, float]] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One robot: arrays (R,).  The single-robot fast path of `cast_robots`."""
        c, s = math.cos(phi), math.sin(phi)
        h = np.array([c, s, x * c, x * s, y * c, y * s, x, y, 1.0])
        return self._solve(h @ self.robot_kernel(bearings, origins), len(bearings), max_range)

    def visible(self, points: np.ndarray, targets: Sequence[float] | np.ndarray) -> np.ndarray:
        """True where no wall properly crosses the straight line from a point to a target.

        points (..., 2); targets (2,) -> result (...), or (T, 2) -> (..., T).
        For line of sight to lamps: orientation tests, linear in the point,
        so one matrix product per call (the per-target matrices are cached).
        Grazing a wall's end point does not block.
        """
        tg = np.asarray(targets, dtype=float)
        single = tg.ndim == 1
        tg = tg.reshape(-1, 2)
        key = tuple(tg.ravel().tolist())
        mats = self._visibility.get(key)
        if mats is None:
            mats = self._visibility[key] = self._visibility_matrices(tg)
        seen = self._visible(np.asarray(points, dtype=float), mats, len(tg))
        return seen[..., 0] if single else seen

    def lamps_visible(self, points: np.ndarray) -> np.ndarray:
        """visible(points, lamp_xy): (..., n_lamps)."""
        if self._lamp_vis is None:
            self._lamp_vis = self._visibility_matrices(self.lamp_xy)
        return self._visible(np.asarray(points, dtype=float), self._lamp_vis, len(self.lamp_xy))

    def _visibility_matrices(self, tg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ax, ay, bx, by = (v[None, :] for v in self.segments.T)  # (1, M)
        lx, ly = tg[:, 0:1], tg[:, 1:2]  # (T, 1)
        ex, ey = bx - ax, by - ay
        one = np.ones_like(lx)
        # orient(A, B, P) = ex (Py - Ay) - ey (Px - Ax), the same for every target
        o_abp = np.stack([-ey * one, ex * one, (ey * ax - ex * ay) * one])
        # orient(P, L, A) = (L - P) x (A - P) = (Lx Ay - Ly Ax) + Px (Ly - Ay) + Py (Ax - Lx)
        o_pla = np.stack([ly - ay, ax - lx, lx * ay - ly * ax])
        o_plb = np.stack([ly - by, bx - lx, lx * by - ly * bx])
        side_l = ex * (ly - ay) - ey * (lx - ax)  # orient(A, B, L), (T, M)
        mat = np.stack([o_abp, o_pla, o_plb], 2)  # (3 features, T, 3, M)
        return mat[:2].reshape(2, -1), (mat[2].reshape(-1), side_l)  # type: ignore[return-value]

    def _visible(self, p: np.ndarray, mats: Any, n_t: int) -> np.ndarray:
        batch = p.shape[:-1]
        m = len(self.segments)
        if m == 0 or n_t == 0:
            return np.ones(batch + (n_t,), dtype=bool)
        o = (p @ mats[0] + mats[1][0]).reshape(batch + (n_t, 3, m))
        crosses = (o[..., 0, :] * mats[1][1] < 0) & (o[..., 1, :] * o[..., 2, :] < 0)
        return ~crosses.any(-1)

    # ------------------------------------------------------------------ distances
    def nearest_wall(self, points: np.ndarray, return_index: bool = False
                     ) -> tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance to the nearest wall and the unit normal from that wall to the point.

        points (..., 2) -> distance (...), normal (..., 2) [, segment index (...)].
        The distance is negative for a point inside a convex obstacle; the
        normal then still points out of the obstacle: moving a point by
        (clearance - distance) along the normal always puts it `clearance`
        from that wall.  A point exactly on a wall gets that wall's geometric
        normal (right of x1,y1 -> x2,y2; outward for a polygon).  No walls:
        distance inf, normal (0, 0).
        """
        p = np.asarray(points, dtype=float)
        batch = p.shape[:-1]
        q = p.reshape(-1, 2)
        m = len(self.segments)
        if m == 0:
            out = (np.full(batch, np.inf), np.zeros(batch + (2,)))
            return out + (np.full(batch, -1),) if return_index else out
        rel = q[:, None, :] - self._a[None]  # (P, M, 2)
        u = np.clip((rel * self._e[None]).sum(-1) / self._len2, 0.0, 1.0)
        diff = rel - u[..., None] * self._e[None]
        d2 = (diff * diff).sum(-1)
        idx = d2.argmin(1)
        rows = np.arange(len(q))
        dist = np.sqrt(d2[rows, idx])
        vec = diff[rows, idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            normal = vec / dist[:, None]
        on_wall = dist < 1e-12
        if on_wall.any():
            normal[on_wall] = self._normal[idx[on_wall]]
        inside = self.inside_obstacle(q)
        if inside.any():
            dist = np.where(inside, -dist, dist)
            normal[inside] = -normal[inside]
        out = (dist.reshape(batch), normal.reshape(batch + (2,)))
        return out + (idx.reshape(batch),) if return_index else out

    def wall_distances(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance from every point to every wall, and the unit normal from the wall to the point.

        points (P, 2) -> distance (P, M), normal (P, M, 2), M = len(segments), in segment
        order.  As nearest_wall, but for all walls at once (contact with several walls,
        corners): the distance to an edge of a convex obstacle the point is inside is
        negative and its normal points out of the obstacle.
        """
        q = np.asarray(points, dtype=float).reshape(-1, 2)
        rel = q[:, None, :] - self._a[None]  # (P, M, 2)
        u = np.clip((rel * self._e[None]).sum(-1) / self._len2, 0.0, 1.0)
        diff = rel - u[..., None] * self._e[None]
        dist = np.sqrt((diff * diff).sum(-1))
        with np.errstate(divide="ignore", invalid="ignore"):
            normal = diff / dist[..., None]
        on_wall = dist < 1e-12
        if on_wall.any():
            normal[on_wall] = np.broadcast_to(self._normal[None], normal.shape)[on_wall]
        if self.polygons:
            excess = q @ self._hp_n.T - self._hp_c  # (P, E)
            inside = np.maximum.reduceat(excess, self._hp_starts, axis=1) < -_EPS  # (P, n_polygons)
            seg_inside = np.zeros(dist.shape, dtype=bool)
            seg_inside[:, self._seg_polygon >= 0] = inside[:, self._seg_polygon[self._seg_polygon >= 0]]
            dist = np.where(seg_inside, -dist, dist)
            normal[seg_inside] = -normal[seg_inside]
        return dist, normal

    def inside_obstacle(self, points: np.ndarray) -> np.ndarray:
        """True where a point is strictly inside one of the convex polygons."""
        p = np.asarray(points, dtype=float)
        batch = p.shape[:-1]
        if not self.polygons:
            return np.zeros(batch, dtype=bool)
        q = p.reshape(-1, 2)
        excess = q @ self._hp_n.T - self._hp_c  # (P, E): > 0 outside that edge
        worst = np.maximum.reduceat(excess, self._hp_starts, axis=1)  # (P, n_polygons)
        return np.asarray((worst < -_EPS).any(1)).reshape(batch)

    # ------------------------------------------------------------------ grids
    def grid_shape(self, resolution: float) -> tuple[int, int]:
        """(ny, nx) of the coverage grid of square cells of side `resolution` over the size.

        WorldError when it has more than MAX_GRID_CELLS cells.
        """
        if not resolution > 0:
            raise WorldError(f"{self.source}: grid resolution must be > 0 m, got {resolution}")
        shape = (max(1, int(math.ceil(self.size[1] / resolution - 1e-9))),
                 max(1, int(math.ceil(self.size[0] / resolution - 1e-9))))
        cells = shape[0] * shape[1]
        if cells > MAX_GRID_CELLS:
            raise WorldError(f"{self.source}: size {self.size[0]:g} m x {self.size[1]:g} m in cells of "
                             f"{resolution:g} m is {shape[1]:,} x {shape[0]:,} = {cells:,} cells; "
                             f"the limit is {MAX_GRID_CELLS:,}")
        return shape

    def cell_centres(self, resolution: float) -> tuple[np.ndarray, np.ndarray]:
        """x (nx,) and y (ny,) of the cell centres; cell [iy, ix] is at (x[ix], y[iy])."""
        ny, nx = self.grid_shape(resolution)
        return (np.arange(nx) + 0.5) * resolution, (np.arange(ny) + 0.5) * resolution

    def cell_of(self, points: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
        """(iy, ix) integer cell indices of points, clipped to the grid."""
        p = np.asarray(points, dtype=float)
        ny, nx = self.grid_shape(resolution)
        ix = np.clip(np.floor(p[..., 0] / resolution).astype(int), 0, nx - 1)
        iy = np.clip(np.floor(p[..., 1] / resolution).astype(int), 0, ny - 1)
        return iy, ix

    def free_cells(self, resolution: float = 0.02, margin: float = DEFAULT_BODY_RADIUS,
                   reachable: bool = False) -> np.ndarray:
        """Boolean grid (ny, nx): cells whose centre a robot centre may occupy.

        A cell is free when its centre is at least `margin` (m; the robot's
        radius, plus any clearance) from every wall and outside every
        obstacle.  reachable=True keeps only the free cells connected
        (4-neighbours) to the start's cell: the area a robot can explore.
        """
        xs, ys = self.cell_centres(resolution)
        # Rows in chunks: nearest_wall holds (points x walls) arrays.
        rows_per_chunk = max(1, 2_000_000 // (len(xs) * max(1, self.n_walls)))
        free = np.empty((len(ys), len(xs)), dtype=bool)
        for r0 in range(0, len(ys), rows_per_chunk):
            gx, gy = np.meshgrid(xs, ys[r0:r0 + rows_per_chunk])
            dist, _ = self.nearest_wall(np.stack([gx, gy], -1))  # type: ignore[misc]
            free[r0:r0 + rows_per_chunk] = dist >= margin
        if reachable:
            free = _flood(free, self.cell_of(np.array(self.start[:2]), resolution))
        return free


def draw_world(ax: Any, world: World, robot_radius: float = DEFAULT_BODY_RADIUS, start: bool = True,
               lamps: bool = True, area: bool = True) -> None:
    """Draw a world on a matplotlib Axes: walls, obstacles, the area of interest, start pose, lamps.

    Needs no matplotlib import here: it only calls methods of `ax`.
    """
    if area:
        w, h = world.size
        ax.plot([0, w, w, 0, 0], [0, 0, h, h, 0], color="0.75", lw=0.8, ls=":", zorder=1)
    for wall in world.walls:
        if "segment" in wall:
            x1, y1, x2, y2 = wall["segment"]
            ax.plot([x1, x2], [y1, y2], color="0.15", lw=2.2, solid_capstyle="round", zorder=3)
        else:
            pts = np.asarray(wall["polygon"])
            ax.fill(pts[:, 0], pts[:, 1], facecolor="0.55", edgecolor="0.15", lw=1.5, zorder=3)
    if start:
        x, y, phi = world.start
        circle = np.linspace(0, 2 * np.pi, 60)
        ax.plot(x + robot_radius * np.cos(circle), y + robot_radius * np.sin(circle), color="tab:blue", lw=1.2,
                zorder=4)
        ax.plot([x, x + robot_radius * math.cos(phi)], [y, y + robot_radius * math.sin(phi)], color="tab:blue",
                lw=1.2, zorder=4)
    if lamps:
        for lamp in world.lamps:
            ax.plot(lamp.x, lamp.y, marker="*", ms=12, color="gold", mec="darkorange", zorder=5, clip_on=False)
    ax.set_aspect("equal")


def _flood(free: np.ndarray, seed: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Cells of `free` connected to `seed` through 4-neighbours."""
    reach = np.zeros_like(free)
    iy, ix = int(seed[0]), int(seed[1])
    if not free[iy, ix]:
        return reach
    reach[iy, ix] = True
    while True:
        grown = reach.copy()
        grown[1:] |= reach[:-1]
        grown[:-1] |= reach[1:]
        grown[:, 1:] |= reach[:, :-1]
        grown[:, :-1] |= reach[:, 1:]
        grown &= free
        if (grown == reach).all():
            return reach
        reach = grown


def _signed_area(pts: np.ndarray) -> float:
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


# --------------------------------------------------------------------------- #
# Loading and validation
# --------------------------------------------------------------------------- #
def _is_num(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _numbers(v: object, n: int | None, where: str, what: str) -> list[float]:
    if not isinstance(v, list) or (n is not None and len(v) != n):
        count = f"{n} " if n is not None else ""
        raise WorldError(f"{where}: {what} must be a list of {count}numbers, got {json.dumps(v)}")
    bad = [i for i, x in enumerate(v) if not _is_num(x)]
    if bad:
        raise WorldError(f"{where}: {what} has an item that is not a finite number "
                         f"(item {bad[0]}: {json.dumps(v[bad[0]])})")
    return [float(x) for x in v]


def _check_polygon(pts_in: object, where: str) -> list[list[float]]:
    if not isinstance(pts_in, list):
        raise WorldError(f"{where}: must be a list of [x, y] points, got {json.dumps(pts_in)}")
    if len(pts_in) < 3:
        raise WorldError(f"{where}: fewer than 3 points ({len(pts_in)}); a polygon needs at least 3")
    pts = [_numbers(p, 2, f"{where}[{k}]", "a point") for k, p in enumerate(pts_in)]
    a = np.asarray(pts)
    n = len(a)
    for k in range(n):
        if math.dist(a[k], a[(k + 1) % n]) < 1e-6:
            raise WorldError(f"{where}: degenerate: points {k} and {(k + 1) % n} coincide")
    crosses = []
    for k in range(n):
        e1 = a[(k + 1) % n] - a[k]
        e2 = a[(k + 2) % n] - a[(k + 1) % n]
        crosses.append(float(e1[0] * e2[1] - e1[1] * e2[0]) / (np.linalg.norm(e1) * np.linalg.norm(e2)))
    for k, c in enumerate(crosses):
        if abs(c) < 1e-9:
            raise WorldError(f"{where}: degenerate: points {k}, {(k + 1) % n} and {(k + 2) % n} are collinear "
                             f"(remove point {(k + 1) % n})")
    sign = 1.0 if sum(crosses) > 0 else -1.0
    for k, c in enumerate(crosses):
        if c * sign < 0:
            raise WorldError(f"{where}: not convex: it turns the other way at point {(k + 1) % n} "
                             f"{pts[(k + 1) % n]} (split it into convex polygons)")
    # All turns the same way is not enough (a pentagram); the turning must total one revolution.
    turning = 0.0
    for k in range(n):
        e1 = a[(k + 1) % n] - a[k]
        e2 = a[(k + 2) % n] - a[(k + 1) % n]
        turning += math.atan2(e1[0] * e2[1] - e1[1] * e2[0], float(e1 @ e2))
    if abs(abs(turning) - 2 * math.pi) > 1e-6:
        raise WorldError(f"{where}: not convex: the outline crosses itself "
                         f"(winds {abs(turning) / (2 * math.pi):.0f} times)")
    if abs(_signed_area(a)) < 1e-8:
        raise WorldError(f"{where}: degenerate: zero area")
    return pts


def world_from_dict(data: object, where: str = "world", body_radius: float = DEFAULT_BODY_RADIUS) -> World:
    """Validate a parsed world file; `where` (the file name) starts every message."""
    if not isinstance(data, dict):
        raise WorldError(f"{where}: expected a JSON object with keys name, size, walls, start, ...")
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise WorldError(f"{where}: unknown key '{unknown[0]}' (allowed: {', '.join(sorted(TOP_KEYS))})")
    for key in ("name", "size", "walls", "start"):
        if key not in data:
            raise WorldError(f"{where}: missing key '{key}'")
    name = data["name"]
    if not isinstance(name, str) or not name:
        raise WorldError(f"{where}: name: must be a non-empty string, got {json.dumps(name)}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise WorldError(f"{where}: description: must be a string")
    size = _numbers(data["size"], 2, f"{where}: size", "size")
    if min(size) <= 0:
        raise WorldError(f"{where}: size: width and height must be positive (m), got {size}")
    if max(size) > MAX_SIZE_M:
        raise WorldError(f"{where}: size: {size[0]:g} m x {size[1]:g} m is too big; the limit is "
                         f"{MAX_SIZE_M:g} m a side")
    walls = _walls_from_list(data["walls"], where)
    _check_extent(walls, where)
    start = _start_from_dict(data["start"], where)
    lamps = _lamps_from_list(data.get("lamps", []), where)
    ambient = data.get("ambient")
    if ambient is not None and (not _is_num(ambient) or not 0 <= ambient <= MAX_LAMP_LEVEL):
        raise WorldError(f"{where}: ambient: must be a number >= 0 and <= {MAX_LAMP_LEVEL:g} (ADC counts), "
                         f"got {json.dumps(ambient)}")

    world = World(name=name, size=(size[0], size[1]), walls=walls, start=start, lamps=tuple(lamps),
                  ambient=None if ambient is None else float(ambient), description=description, source=where)
    _check_grid(world, where)
    _check_start_is_clear(world, where, body_radius)
    return world


def _walls_from_list(walls_in: object, where: str) -> list[dict[str, Any]]:
    """The "walls" entries, each {"segment": [x1, y1, x2, y2]} or {"polygon": [[x, y], ...]}."""
    if not isinstance(walls_in, list):
        raise WorldError(f"{where}: walls: must be a list of {{\"segment\": ...}} or {{\"polygon\": ...}} entries")
    walls: list[dict[str, Any]] = []
    for i, wall in enumerate(walls_in):
        here = f"{where}: walls[{i}]"
        if not isinstance(wall, dict) or len(wall) != 1 or next(iter(wall)) not in ("segment", "polygon"):
            keys = list(wall) if isinstance(wall, dict) else None
            raise WorldError(f"{here}: must be an object with exactly one key, 'segment' or 'polygon' "
                             f"(got {json.dumps(keys) if keys is not None else json.dumps(wall)})")
        if "segment" in wall:
            seg = _numbers(wall["segment"], 4, f"{here}.segment", "a segment [x1, y1, x2, y2]")
            if math.hypot(seg[2] - seg[0], seg[3] - seg[1]) < 1e-6:
                raise WorldError(f"{here}.segment: degenerate: both ends are the same point")
            walls.append({"segment": seg})
        else:
            walls.append({"polygon": _check_polygon(wall["polygon"], f"{here}.polygon")})
    return walls


def _start_from_dict(start_in: object, where: str) -> tuple[float, float, float]:
    """The "start" pose {"x": m, "y": m, "phi": rad}."""
    if not isinstance(start_in, dict):
        raise WorldError(f"{where}: start: must be an object {{\"x\": m, \"y\": m, \"phi\": rad}}")
    extra = sorted(set(start_in) - {"x", "y", "phi"})
    if extra:
        raise WorldError(f"{where}: start: unknown key '{extra[0]}' (allowed: x, y, phi)")
    for key in ("x", "y", "phi"):
        if key not in start_in:
            raise WorldError(f"{where}: start: missing '{key}'")
        if not _is_num(start_in[key]):
            raise WorldError(f"{where}: start.{key}: not a finite number ({json.dumps(start_in[key])})")
    return (float(start_in["x"]), float(start_in["y"]), float(start_in["phi"]))


def _lamps_from_list(lamps_in: object, where: str) -> list[Lamp]:
    """The optional "lamps": {"x", "y", "level"[, "flicker_hz", "flicker_depth"]} each."""
    if not isinstance(lamps_in, list):
        raise WorldError(f"{where}: lamps: must be a list of {{\"x\", \"y\", \"level\"}} objects")
    lamps: list[Lamp] = []
    for i, lamp in enumerate(lamps_in):
        here = f"{where}: lamps[{i}]"
        if not isinstance(lamp, dict):
            raise WorldError(f"{here}: must be an object with x, y, level")
        extra = sorted(set(lamp) - LAMP_KEYS)
        if extra:
            raise WorldError(f"{here}: unknown key '{extra[0]}' (allowed: {', '.join(sorted(LAMP_KEYS))})")
        for key in ("x", "y", "level"):
            if key not in lamp:
                raise WorldError(f"{here}: missing '{key}'")
        for key, value in lamp.items():
            if not _is_num(value):
                raise WorldError(f"{here}.{key}: not a finite number ({json.dumps(value)})")
        if not 0 <= lamp["level"] <= MAX_LAMP_LEVEL:
            raise WorldError(f"{here}.level: must be in 0..{MAX_LAMP_LEVEL:g} (ADC counts at 1 m), "
                             f"got {lamp['level']}")
        if not 0 <= lamp.get("flicker_hz", 0) <= MAX_FLICKER_HZ:
            raise WorldError(f"{here}.flicker_hz: must be in 0..{MAX_FLICKER_HZ:g} Hz, got {lamp['flicker_hz']}")
        if max(abs(lamp["x"]), abs(lamp["y"])) > MAX_COORD_M:
            raise WorldError(f"{here}: ({lamp['x']}, {lamp['y']}) is more than {MAX_COORD_M:g} m from the origin "
                             f"on an axis")
        depth = lamp.get("flicker_depth", DEFAULT_FLICKER_DEPTH)
        if not 0 <= depth <= 1:
            raise WorldError(f"{here}.flicker_depth: must be in [0, 1], got {depth}")
        lamps.append(Lamp(float(lamp["x"]), float(lamp["y"]), float(lamp["level"]),
                          float(lamp.get("flicker_hz", 0.0)), float(depth)))
    return lamps


def _check_extent(walls: list[dict[str, Any]], where: str) -> None:
    """Every wall point within MAX_COORD_M; at most MAX_SEGMENTS segments."""
    n_segments = 0
    for i, wall in enumerate(walls):
        points = wall["segment"] if "segment" in wall else [v for pt in wall["polygon"] for v in pt]
        n_segments += 1 if "segment" in wall else len(wall["polygon"])
        if max(abs(v) for v in points) > MAX_COORD_M:
            kind = "segment" if "segment" in wall else "polygon"
            raise WorldError(f"{where}: walls[{i}].{kind}: a coordinate is beyond +-{MAX_COORD_M:g} m")
    if n_segments > MAX_SEGMENTS:
        raise WorldError(f"{where}: walls: {n_segments:,} segments (polygon edges included); "
                         f"the limit is {MAX_SEGMENTS:,}")


def _check_grid(world: World, where: str) -> None:
    """The coverage grid fits, and measuring its cells against the walls stays quick."""
    ny, nx = world.grid_shape(GRID_RESOLUTION)
    work = nx * ny * max(1, world.n_walls)
    if work > MAX_GRID_WORK:
        raise WorldError(f"{where}: {nx * ny:,} coverage cells of {GRID_RESOLUTION:g} m times {world.n_walls:,} "
                         f"wall segments is {work:,} distances to compute; the limit is {MAX_GRID_WORK:,} "
                         f"(a smaller size or fewer walls)")


def _check_start_is_clear(world: World, where: str, body_radius: float) -> None:
    """The start pose: inside the area, clear of every wall."""
    start, size = world.start, world.size
    if world.outside(np.array(start[:2])):
        raise WorldError(f"{where}: start: ({start[0]}, {start[1]}) is outside the world's size "
                         f"[0, {size[0]}] x [0, {size[1]}]")
    if world.n_walls:
        dist, _, nearest = world.nearest_wall(np.array(start[:2]), return_index=True)  # type: ignore[misc]
        if dist < body_radius:
            entry = int(world.segment_entry[int(nearest)])
            kind = "segment" if "segment" in world.walls[entry] else "polygon"
            problem = "is inside" if dist < 0 else f"overlaps (centre {float(dist):.3f} m from it)"
            raise WorldError(f"{where}: start: the robot (radius {body_radius} m) at ({start[0]}, {start[1]}) "
                             f"{problem} walls[{entry}].{kind}")


def load_world(path: str | Path, body_radius: float = DEFAULT_BODY_RADIUS) -> World:
    """Read and validate a world file; WorldError names the file, the entry and the problem."""
    path = Path(path)
    return world_from_dict(read_json(path, "world file", WorldError), str(path), body_radius)


def save_world(world: World, path: str | Path) -> None:
    """Write a world as JSON; `load_world` reads it back to an equal world."""
    Path(path).write_text(json.dumps(world.to_dict(), indent=1) + "\n")


def builtin_world(name: str, body_radius: float = DEFAULT_BODY_RADIUS) -> World:
    """One of BUILTIN_NAMES ("paper_room", "maze", "arena")."""
    path = WORLDS_DIR / f"{name}.json"
    if name not in BUILTIN_NAMES or not path.is_file():
        raise WorldError(f"no built-in world '{name}' (built-in: {', '.join(BUILTIN_NAMES)})")
    return load_world(path, body_radius)


def world_by_name_or_path(text: str | Path, body_radius: float = DEFAULT_BODY_RADIUS) -> World:
    """A built-in world's name, or the path of a world file."""
    if str(text) in BUILTIN_NAMES:
        return builtin_world(str(text), body_radius)
    path = Path(text)
    if not path.exists() and path.suffix != ".json":
        raise WorldError(f"{text}: neither a built-in world ({', '.join(BUILTIN_NAMES)}) nor a file")
    return load_world(path, body_radius)
