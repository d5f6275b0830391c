"""Drawing: the room, the robots, their rays and bars, coverage, the plot, buttons and text.

Only pygame drawing lives here; what to draw comes from render.py.  Costly things are cached: rendered
text by (string, colour, size), the grid by the view, the coverage overlay by (covered count, view).
See docs/gui.md.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
import pygame

from tools.gui.view import Viewport

BG = (250, 250, 247)
PANEL = (236, 238, 242)
GRID = (228, 228, 222)
GRID_MAJOR = (210, 210, 204)
WALL = (40, 40, 48)
SELECTED = (220, 30, 160)
PREVIEW = (120, 120, 200)
AREA = (170, 170, 160)
COVERED = (255, 234, 160)
KEY = (255, 0, 255)  # colour key: transparent
TEXT = (30, 30, 35)
DIM = (110, 110, 120)
RED = (220, 40, 40)
COLOURS = {"simulated": (40, 100, 230), "user": (20, 150, 60), "real": (235, 120, 20)}
GHOST = (150, 40, 200)  # the real robot's ghost: where it is now, by the late-signal twin


class Painter:
    def __init__(self, surface: pygame.Surface) -> None:
        self.surface = surface
        self.fonts = {size: pygame.font.Font(None, size) for size in (16, 18, 20, 24)}
        self._text: dict[tuple[str, tuple[int, int, int], int], pygame.Surface] = {}
        self._grid_key: tuple[Any, ...] | None = None
        self._grid: pygame.Surface | None = None
        self._cov_key: tuple[Any, ...] | None = None
        self._cov: pygame.Surface | None = None
        self._trails: dict[tuple[Any, ...], list[tuple[int, int]]] = {}
        self._discs: dict[tuple[int, tuple[int, int, int]], pygame.Surface] = {}
        self.drawn: list[str] = []  # every text drawn since the frame began (what the tests read)

    def text(self, s: str, pos: tuple[int, int], colour: tuple[int, int, int] = TEXT, size: int = 20,
             anchor: str = "topleft") -> pygame.Rect:
        self.drawn.append(s)
        key = (s, colour, size)
        img = self._text.get(key)
        if img is None:
            if len(self._text) > 2000:
                self._text.clear()
            img = self.fonts[size].render(s, True, colour)
            self._text[key] = img
        rect = img.get_rect(**{anchor: pos})
        self.surface.blit(img, rect)
        return rect

    # -- the room ---------------------------------------------------------
    def grid(self, view: Viewport, spacing: float, size: tuple[float, float]) -> None:
        key = (view.version, view.rect, spacing, size)
        if key != self._grid_key:
            self._grid_key, self._grid = key, self._render_grid(view, spacing, size).convert()
        assert self._grid is not None
        self.surface.blit(self._grid, view.rect[:2])

    def _render_grid(self, view: Viewport, spacing: float, size: tuple[float, float]) -> pygame.Surface:
        rx, ry, w, h = view.rect
        surf = pygame.Surface((w, h))
        surf.fill(BG)
        x0, y0 = view.to_world(rx, ry + h)
        x1, y1 = view.to_world(rx + w, ry)
        step = spacing if spacing * view.scale >= 6 else spacing * math.ceil(6 / (spacing * view.scale))
        for k in range(math.floor(x0 / step), math.ceil(x1 / step) + 1):
            sx = view.to_screen(k * step, 0)[0] - rx
            major = abs(k * step / 0.5 - round(k * step / 0.5)) < 1e-6
            pygame.draw.line(surf, GRID_MAJOR if major else GRID, (sx, 0), (sx, h))
        for k in range(math.floor(y0 / step), math.ceil(y1 / step) + 1):
            sy = view.to_screen(0, k * step)[1] - ry
            major = abs(k * step / 0.5 - round(k * step / 0.5)) < 1e-6
            pygame.draw.line(surf, GRID_MAJOR if major else GRID, (0, sy), (w, sy))
        a, b = view.to_screen(0, size[1]), view.to_screen(size[0], 0)
        pygame.draw.rect(surf, AREA, pygame.Rect(a[0] - rx, a[1] - ry, b[0] - a[0], b[1] - a[1]), 1)
        return surf

    def walls(self, view: Viewport, walls: Sequence[dict[str, Any]], selected: int | None) -> None:
        width = max(2, int(view.scale * 0.006))
        for i, wall in enumerate(walls):
            colour = SELECTED if i == selected else WALL
            if "segment" in wall:
                x1, y1, x2, y2 = wall["segment"]
                pygame.draw.line(self.surface, colour, view.to_screen(x1, y1), view.to_screen(x2, y2), width)
            else:
                pts = [view.to_screen(x, y) for x, y in wall["polygon"]]
                pygame.draw.polygon(self.surface, (150, 150, 158) if i != selected else SELECTED, pts)
                pygame.draw.polygon(self.surface, colour, pts, width)

    def preview(self, view: Viewport, kind: str, a: tuple[float, float], b: tuple[float, float]) -> None:
        if kind == "box":
            corners = [(a[0], a[1]), (b[0], a[1]), (b[0], b[1]), (a[0], b[1])]
            pygame.draw.polygon(self.surface, PREVIEW, [view.to_screen(*c) for c in corners], 3)
        else:
            pygame.draw.line(self.surface, PREVIEW, view.to_screen(*a), view.to_screen(*b), 3)
        for p in (a, b):
            pygame.draw.circle(self.surface, PREVIEW, view.to_screen(*p), 4)

    def corners(self, view: Viewport, corners: Sequence[tuple[float, float]], pointer: tuple[float, float]) -> None:
        """The polygon being drawn: its corners, and the edge to the pointer."""
        pts = [view.to_screen(*c) for c in corners]
        if len(pts) >= 2:
            pygame.draw.lines(self.surface, PREVIEW, False, pts, 3)
        pygame.draw.line(self.surface, PREVIEW, pts[-1], view.to_screen(*pointer), 1)
        for p in pts:
            pygame.draw.circle(self.surface, PREVIEW, p, 4)

    def coverage(self, view: Viewport, covered: np.ndarray, count: int, resolution: float) -> None:
        """The covered cells of the free grid (row 0 at y = 0), over the floor.

        Opaque with a colour key (the uncovered cells), converted to the
        display's format: a translucent overlay this size costs ~8 ms a blit.
        """
        ny, nx = covered.shape
        key = (count, view.version, view.rect, covered.shape)
        if key != self._cov_key:
            rgb = np.empty((nx, ny, 3), np.uint8)  # surfarray is indexed [x, y]
            rgb[:] = KEY
            rgb[covered.T[:, ::-1]] = COVERED
            small = pygame.surfarray.make_surface(rgb)
            size = (max(1, int(round(nx * resolution * view.scale))), max(1, int(round(ny * resolution * view.scale))))
            self._cov = pygame.transform.scale(small, size).convert()
            self._cov.set_colorkey(KEY, pygame.RLEACCEL)
            self._cov_key = key
        assert self._cov is not None
        self.surface.blit(self._cov, view.to_screen(0.0, ny * resolution))

    # -- robots -------------------------------------------------------------
    def trail(self, view: Viewport, trail: Sequence[tuple[float, float, float]], colour: tuple[int, int, int],
              keep: int = 4000) -> None:
        """The last `keep` poses as a line; their pixels are converted once each (until the view changes)."""
        key = (id(trail), view.version, view.rect)
        done = self._trails.get(key)
        if done is None or len(done) > len(trail):
            self._trails = {k: v for k, v in self._trails.items() if k[0] != id(trail)}
            done = self._trails[key] = []
        if len(trail) > len(done):
            new = np.asarray(trail[len(done):], dtype=float).reshape(-1, 3)[:, :2]
            done.extend(map(tuple, view.to_screen_array(new).round().astype(int).tolist()))
        if len(done) >= 2:
            light = (int(colour[0] + (255 - colour[0]) * 0.55), int(colour[1] + (255 - colour[1]) * 0.55),
                     int(colour[2] + (255 - colour[2]) * 0.55))
            pygame.draw.lines(self.surface, light, False, done[-keep:], 2)

    def robot(self, view: Viewport, pose: tuple[float, float, float], radius: float, colour: tuple[int, int, int],
              contact: bool = False) -> None:
        x, y, phi = pose
        centre = view.to_screen(x, y)
        r = max(3, int(radius * view.scale))
        fill = tuple(int(c + (255 - c) * 0.35) for c in colour)
        pygame.draw.circle(self.surface, fill, centre, r)
        pygame.draw.circle(self.surface, RED if contact else colour, centre, r, 3 if contact else 2)
        nose = view.to_screen(x + radius * math.cos(phi), y + radius * math.sin(phi))
        pygame.draw.line(self.surface, (20, 20, 20), centre, nose, 3)

    def ghost(self, view: Viewport, raw: tuple[float, float, float], pose: tuple[float, float, float],
              radius: float, label: str) -> None:
        """The ghost: a translucent body outlined in GHOST, its heading, a line from the raw late pose, a label."""
        x, y, phi = pose
        centre = view.to_screen(x, y)
        r = max(3, int(radius * view.scale))
        disc = self._discs.get((r, GHOST))
        if disc is None:  # one translucent disc per size, drawn once
            disc = self._discs[(r, GHOST)] = pygame.Surface((2 * r + 1, 2 * r + 1), pygame.SRCALPHA)
            pygame.draw.circle(disc, (*GHOST, 70), (r, r), r)
        self.surface.blit(disc, (centre[0] - r, centre[1] - r))
        pygame.draw.line(self.surface, GHOST, view.to_screen(raw[0], raw[1]), centre, 1)
        pygame.draw.circle(self.surface, GHOST, centre, r, 2)
        nose = view.to_screen(x + radius * math.cos(phi), y + radius * math.sin(phi))
        pygame.draw.line(self.surface, GHOST, centre, nose, 3)
        self.text(label, (centre[0] + r + 3, centre[1] - r - 2), GHOST, 16, "bottomleft")

    def rays(self, view: Viewport, rays: np.ndarray, counts: Sequence[int], colour: tuple[int, int, int],
             full_scale: float) -> None:
        for (x0, y0, x1, y1), c in zip(rays, counts):
            strength = min(1.0, c / full_scale)
            shade = tuple(int(255 - (255 - k) * (0.25 + 0.75 * strength)) for k in colour)
            pygame.draw.line(self.surface, shade, view.to_screen(x0, y0), view.to_screen(x1, y1),
                             1 + int(2 * strength))

    def start(self, view: Viewport, pose: tuple[float, float, float], handle: tuple[float, float], radius: float,
              blocked: bool) -> None:
        """The start pose: its outline, an arrow along its heading to the handle the mouse grabs; red if blocked."""
        colour = RED if blocked else DIM
        centre, tip = view.to_screen(pose[0], pose[1]), view.to_screen(*handle)
        pygame.draw.circle(self.surface, colour, centre, max(3, int(radius * view.scale)), 1)
        pygame.draw.line(self.surface, colour, centre, tip, 2)
        pygame.draw.circle(self.surface, colour, tip, 5)
        self.text("start: a wall crosses it" if blocked else "start", (tip[0] + 7, tip[1]), colour, 16, "midleft")

    def marks(self, view: Viewport, points: Sequence[tuple[float, float]], colour: tuple[int, int, int]) -> None:
        for x, y in points[-200:]:
            sx, sy = view.to_screen(x, y)
            pygame.draw.line(self.surface, colour, (sx - 4, sy - 4), (sx + 4, sy + 4), 2)
            pygame.draw.line(self.surface, colour, (sx - 4, sy + 4), (sx + 4, sy - 4), 2)

    def crossings(self, view: Viewport, points: Sequence[tuple[float, float]], label: str) -> None:
        """Rings where a trail crossed a wall; the first one labelled."""
        for k, (x, y) in enumerate(points[-200:]):
            centre = view.to_screen(x, y)
            pygame.draw.circle(self.surface, RED, centre, 7, 2)
            if k == 0:
                self.text(label, (centre[0] + 9, centre[1]), RED, 16, "midleft")

    def flag(self, view: Viewport, x: float, y: float) -> None:
        sx, sy = view.to_screen(x, y)
        pygame.draw.line(self.surface, TEXT, (sx, sy), (sx, sy - 26), 2)
        pygame.draw.polygon(self.surface, (30, 180, 60), [(sx, sy - 26), (sx + 16, sy - 21), (sx, sy - 16)])
        self.text("exit", (sx + 4, sy - 14), TEXT, 16)

    # -- panel --------------------------------------------------------------
    def bars(self, rect: pygame.Rect, counts: Sequence[int], colour: tuple[int, int, int], full_scale: float) -> None:
        pygame.draw.rect(self.surface, (255, 255, 255), rect)
        n = len(counts)
        w = rect.width / n
        for i, c in enumerate(counts):
            h = int(rect.height * min(1.0, c / full_scale))
            pygame.draw.rect(self.surface, colour, (int(rect.x + i * w + 2), rect.bottom - h, int(w - 4), h))
            self.text(f"S{i + 1}", (int(rect.x + i * w + w / 2), rect.bottom + 1), DIM, 16, "midtop")
            self.text(f"{c}", (int(rect.x + i * w + w / 2), rect.y + 2), TEXT, 16, "midtop")
        pygame.draw.rect(self.surface, DIM, rect, 1)

    def setpoints(self, rect: pygame.Rect, left: int, right: int, limit: int, colour: tuple[int, int, int]) -> None:
        """Two wheel-speed bars around a centre line, -limit..+limit."""
        pygame.draw.rect(self.surface, (255, 255, 255), rect)
        mid = rect.centerx
        half = rect.width / 2
        for row, (name, v) in enumerate((("L", left), ("R", right))):
            y = rect.y + 4 + row * (rect.height // 2)
            w = int(half * max(-1.0, min(1.0, v / limit))) if limit else 0
            bar = pygame.Rect(min(mid, mid + w), y, abs(w), rect.height // 2 - 8)
            pygame.draw.rect(self.surface, colour, bar)
            self.text(f"{name} {v:+d}", (rect.x + 3, y), TEXT, 16)
        pygame.draw.line(self.surface, DIM, (mid, rect.y), (mid, rect.bottom))
        pygame.draw.rect(self.surface, DIM, rect, 1)

    def plot(self, rect: pygame.Rect, t: list[float], frac: list[float], t90: float | None) -> None:
        """Coverage against time, 0..100 %, with the 90 % line; both axes labelled."""
        pygame.draw.rect(self.surface, (255, 255, 255), rect)
        y90 = rect.bottom - int(0.9 * rect.height)
        pygame.draw.line(self.surface, GRID_MAJOR, (rect.x, y90), (rect.right, y90))
        self.text("90 %", (rect.right - 2, y90 + 1), DIM, 16, "topright")
        for pct in (0, 50, 100):
            self.text(f"{pct}", (rect.x - 2, rect.bottom - int(pct / 100 * rect.height)), DIM, 16, "midright")
        self.text("coverage, %", (rect.x + 2, rect.y + 2), DIM, 16)
        self.text("0", (rect.x, rect.bottom + 1), DIM, 16, "midtop")
        self.text("time, s", (rect.centerx, rect.bottom + 1), DIM, 16, "midtop")
        if len(t) >= 2:
            step = max(1, len(t) // 400)
            tt = np.asarray(t[::step] + [t[-1]])
            ff = np.asarray(frac[::step] + [frac[-1]])
            span = max(float(tt[-1]), 10.0)
            xs = rect.x + tt / span * rect.width
            ys = rect.bottom - ff * rect.height
            pygame.draw.lines(self.surface, COLOURS["simulated"], False, np.stack([xs, ys], 1).tolist(), 2)
            self.text(f"{span:.0f} s", (rect.right, rect.bottom + 1), DIM, 16, "topright")
        if t90 is not None:
            self.text(f"90 % at {t90:.1f} s", (rect.x + 4, y90 - 14), TEXT, 16)
        pygame.draw.rect(self.surface, DIM, rect, 1)

    def button(self, rect: pygame.Rect, label: str, on: bool, hover: bool) -> None:
        fill = (200, 220, 250) if on else (252, 252, 252)
        if hover:
            fill = (fill[0] - 18, fill[1] - 18, fill[2] - 18)
        pygame.draw.rect(self.surface, fill, rect, border_radius=4)
        pygame.draw.rect(self.surface, DIM, rect, 1, border_radius=4)
        self.text(label, rect.center, TEXT, 16, "center")

    def overlay(self, lines: Sequence[str], rect: pygame.Rect, pitch: int = 19) -> None:
        """Lines of text on a white box, pitch pixels apart (a smaller font below 18)."""
        box = pygame.Surface(rect.size, pygame.SRCALPHA)
        box.fill((255, 255, 255, 235))
        self.surface.blit(box, rect)
        pygame.draw.rect(self.surface, DIM, rect, 1)
        size = 20 if pitch >= 18 else 18
        for i, line in enumerate(lines):
            y = rect.y + 10 + pitch * i
            if "\t" in line:  # key \t what it does: two columns
                k, what = line.split("\t", 1)
                self.text(k, (rect.x + 70, y), TEXT, size, "topright")
                self.text(what, (rect.x + 86, y), TEXT, size)
            else:
                self.text(line, (rect.x + 14, y), TEXT, size)
