"""The replay panel drawn: the recorded robot in the room at the slider's time, the slider, and plots over
time of the IR readings, the wheel speeds and the commands, with a cursor at the slider's time and the
diagnosis's located spans as coloured bands.  Its state is tools/gui/replay.py.  See docs/gui.md.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import pygame

from host_sim.physics.params import RobotParams
from host_sim.physics.world import World
from tools.gui import draw, overlays
from tools.gui.replay import Replay, Replayed
from tools.gui.robots import rays
from tools.gui.view import Viewport

REPLAY = (0, 140, 140)  # the recorded robot, its path and the slider
CURSOR = (200, 30, 30)
LEFT = (40, 100, 230)  # the left wheel's lines; the right's are RIGHT
RIGHT = (235, 120, 20)
SENSOR_COLOURS = ((220, 40, 40), (235, 120, 20), (190, 170, 0), (40, 160, 60), (0, 150, 170), (40, 100, 230),
                  (130, 60, 200), (200, 40, 150))  # S1..S8
BANDS = (((255, 205, 205), (190, 30, 30)), ((205, 225, 255), (30, 80, 200)), ((210, 240, 200), (40, 130, 40)),
         ((250, 228, 195), (190, 110, 20)), ((232, 212, 250), (120, 50, 180)), ((250, 245, 180), (140, 120, 0)))
PLOT_LEFT = 64  # pixels left of the plots for their scales
PLOTS_TOP = 60  # the plots under the header's three lines and the slider
PLOT_H, PLOT_GAP = 54, 4
FULL_SCALE = 4095.0


def close_box(strip: pygame.Rect) -> pygame.Rect:
    return pygame.Rect(strip.right - 24, strip.y + 4, 18, 18)


def plot_rects(strip: pygame.Rect) -> list[pygame.Rect]:
    """The IR, wheel-speed and command plots, stacked, sharing one time axis."""
    width = strip.width - PLOT_LEFT - 14
    return [pygame.Rect(strip.x + PLOT_LEFT, strip.y + PLOTS_TOP + k * (PLOT_H + PLOT_GAP), width, PLOT_H)
            for k in range(3)]


def x_at(rect: pygame.Rect, t: float, t0: float, t1: float) -> int:
    return int(round(rect.x + (t - t0) / max(t1 - t0, 1e-9) * (rect.width - 1)))


def time_at(strip: pygame.Rect, x: int, t0: float, t1: float) -> float:
    """The time under screen column x on the slider or a plot (clipped to the recording)."""
    rect = plot_rects(strip)[0]
    return t0 + min(1.0, max(0.0, (x - rect.x) / max(rect.width - 1, 1))) * (t1 - t0)


class ReplayView:
    """Draws the panel with the window's Painter; what it drew last is kept for the tests."""

    def __init__(self, painter: draw.Painter) -> None:
        self.p = painter
        self._plots_key: tuple[Any, ...] | None = None
        self._plots: pygame.Surface | None = None
        self._path_key: tuple[Any, ...] | None = None
        self._path: tuple[np.ndarray, list[tuple[int, int]]] = (np.zeros(0, int), [])
        self.robot_drawn: tuple[float, float, float] | None = None  # the recorded pose drawn in the room
        self.cursor_x: int | None = None  # the plots' cursor, screen x
        self.bands: list[tuple[str, float, float, pygame.Rect]] = []  # (channel, t0, t1, its band on the plots)

    # -- the room -------------------------------------------------------------
    def room(self, view: Viewport, replay: Replay, world: World, params: RobotParams) -> None:
        """The recorded robot at the slider's time: its whole path faint, the part driven so far, its body, rays
        and counts, labelled."""
        shown = replay.shown
        assert shown is not None
        k = shown.index(replay.time)
        rows, points = self._screen_path(view, shown)
        light = tuple(int(c + (255 - c) * 0.7) for c in REPLAY)
        if len(points) >= 2:
            pygame.draw.lines(self.p.surface, light, False, points, 1)
        done = points[:int(np.searchsorted(rows, k, side="right"))] + [view.to_screen(*shown.pose[k, :2])]
        if len(done) >= 2:
            pygame.draw.lines(self.p.surface, REPLAY, False, done, 2)
        pose = (float(shown.pose[k, 0]), float(shown.pose[k, 1]), float(shown.pose[k, 2]))
        counts = [int(c) for c in shown.ir[k]]
        self.p.rays(view, rays(world, pose, params), counts, REPLAY, FULL_SCALE)
        self.p.robot(view, pose, params.body_radius, REPLAY)
        overlays.sensors(self.p, view, pose, params.body_radius, counts, REPLAY)
        sx, sy = view.to_screen(pose[0], pose[1])
        r = int(params.body_radius * view.scale)
        self.p.text(f"recorded, t = {shown.t[k]:.2f} s", (sx + r + 4, sy + r + 2), REPLAY, 16)
        self.robot_drawn = pose

    def _screen_path(self, view: Viewport, shown: Replayed) -> tuple[np.ndarray, list[tuple[int, int]]]:
        """The recorded path's rows (at most ~4000) and their pixels, until the view changes."""
        key = (id(shown), view.version, view.rect)
        if key != self._path_key:
            rows = np.arange(0, len(shown.t), max(1, len(shown.t) // 4000))
            px = view.to_screen_array(shown.pose[rows, :2]).round().astype(int)
            self._path_key, self._path = key, (rows, [tuple(p) for p in px.tolist()])
        return self._path

    # -- the panel -------------------------------------------------------------
    def strip(self, strip: pygame.Rect, replay: Replay) -> None:
        shown = replay.shown
        assert shown is not None
        p, surf = self.p, self.p.surface
        pygame.draw.rect(surf, draw.PANEL, strip)
        pygame.draw.line(surf, draw.DIM, strip.topleft, strip.topright)
        t0, t1 = float(shown.t[0]), float(shown.t[-1])
        k = shown.index(replay.time)
        x = strip.x + 8
        p.text(f"replay: {shown.path.name}   t = {replay.time:.2f} s of {t0:.2f} .. {t1:.2f} s   row {k + 1} / "
               f"{len(shown.t)}{'   PLAYING' if replay.playing else ''}", (x, strip.y + 3), draw.TEXT, 18)
        box = close_box(strip)
        pygame.draw.rect(surf, (252, 252, 252), box, border_radius=3)
        pygame.draw.rect(surf, draw.DIM, box, 1, border_radius=3)
        p.text("x", box.center, draw.TEXT, 18, "center")
        p.text(f"robot drawn from: {shown.pose_source}   |   drag the slider or a plot; PgUp/PgDn 1 s; j plays",
               (x, strip.y + 19), draw.DIM, 16)
        self.verdict(replay, (x, strip.y + 34))
        plots = plot_rects(strip)
        bands = self._bands(replay, plots, t0, t1)
        surf.blit(self._plot_surface(shown, plots, bands, t0, t1), plots[0].topleft)
        self.scales(shown, plots, t0, t1)
        self.slider(plots[0], strip.y + 52, replay.time, t0, t1)
        self.cursor_x = x_at(plots[0], replay.time, t0, t1)
        pygame.draw.line(surf, CURSOR, (self.cursor_x, plots[0].y), (self.cursor_x, plots[-1].bottom), 2)

    def verdict(self, replay: Replay, pos: tuple[int, int]) -> None:
        """The diagnosis's line: how long it has run, or its verdict and a legend of the located spans' bands."""
        job = replay.job
        if job is None:
            self.p.text("d: diagnose this recording (the verdict and where it disagrees with the twin show here)",
                        pos, draw.DIM, 16)
            return
        colour = draw.TEXT if job.result is not None or job.running else draw.RED
        x = self.p.text(job.verdict(), pos, colour, 16).right + 12
        for i, (channel, _spans) in enumerate(job.located()):
            tint, dark = BANDS[i % len(BANDS)]
            pygame.draw.rect(self.p.surface, tint, (x, pos[1] + 1, 12, 11))
            x = self.p.text(channel, (x + 15, pos[1]), dark, 16).right + 10

    def _bands(self, replay: Replay, plots: list[pygame.Rect], t0: float, t1: float
               ) -> list[tuple[str, float, float, pygame.Rect]]:
        job = replay.job
        self.bands = []
        for i, (channel, spans) in enumerate(job.located() if job is not None and not job.running else []):
            for a, b in spans:
                xa, xb = x_at(plots[0], a, t0, t1), x_at(plots[0], b, t0, t1)
                self.bands.append((channel, a, b, pygame.Rect(xa, plots[0].y, max(2, xb - xa),
                                                              plots[-1].bottom - plots[0].y)))
        return self.bands

    def _plot_surface(self, shown: Replayed, plots: list[pygame.Rect], bands: Sequence[tuple[str, float, float,
                      pygame.Rect]], t0: float, t1: float) -> pygame.Surface:
        """The three plots' backgrounds, bands and lines, drawn once per recording, size and diagnosis."""
        key = (id(shown), tuple(map(tuple, plots)), tuple((c, a, b) for c, a, b, _r in bands))
        if key == self._plots_key and self._plots is not None:
            return self._plots
        top = plots[0].topleft
        surf = pygame.Surface((plots[0].width, plots[-1].bottom - plots[0].y))
        surf.fill(draw.PANEL)
        local = [r.move(-top[0], -top[1]) for r in plots]
        channels = list(dict.fromkeys(c for c, *_ in bands))
        for r in local:
            pygame.draw.rect(surf, (255, 255, 255), r)
            for channel, _a, _b, band in bands:
                tint = BANDS[channels.index(channel) % len(BANDS)][0]
                pygame.draw.rect(surf, tint, (band.x - top[0], r.y, band.width, r.height))
        for r, lines, (lo, hi) in zip(local, plot_lines(shown), plot_ranges(shown)):
            if lo < 0:  # the zero line
                y0 = r.bottom - 1 - int(-lo / (hi - lo) * (r.height - 2))
                pygame.draw.line(surf, draw.GRID_MAJOR, (r.x, y0), (r.right - 1, y0))
            for values, colour, width in lines:
                _line(surf, r, shown.t, values, lo, hi, colour, width, t0, t1)
        for r in local:
            pygame.draw.rect(surf, draw.DIM, r, 1)
        self._plots_key, self._plots = key, surf.convert()
        return self._plots

    def scales(self, shown: Replayed, plots: list[pygame.Rect], t0: float, t1: float) -> None:
        """Each plot's name, its range and legend; the time axis under the last."""
        p = self.p
        titles = ("IR, reflected counts", "wheel speed, mm/s (encoders; thin: set-points)",
                  "commands: current references, mA")
        for series, (rect, (lo, hi), title) in enumerate(zip(plots, plot_ranges(shown), titles)):
            p.text(f"{hi:.0f}", (rect.x - 3, rect.y), draw.DIM, 16, "topright")
            p.text(f"{lo:.0f}", (rect.x - 3, rect.bottom), draw.DIM, 16, "bottomright")
            p.text(title, (rect.x + 4, rect.y + 2), draw.DIM, 16)
            names = [f"S{i + 1}" for i in range(8)] if series == 0 else ["L", "R"]
            colours = SENSOR_COLOURS if series == 0 else (LEFT, RIGHT)
            x = rect.right - 4
            for name, colour in reversed(list(zip(names, colours))):
                x = p.text(name, (x, rect.y + 2), colour, 16, "topright").x - 5
        last = plots[-1]
        p.text(f"{t0:.1f}", (last.x, last.bottom + 1), draw.DIM, 16)
        p.text(f"{t1:.1f} s", (last.right, last.bottom + 1), draw.DIM, 16, "topright")
        p.text("time, s", (last.centerx, last.bottom + 1), draw.DIM, 16, "midtop")

    def slider(self, rect: pygame.Rect, y: int, t: float, t0: float, t1: float) -> None:
        surf = self.p.surface
        pygame.draw.line(surf, draw.DIM, (rect.x, y), (rect.right - 1, y), 4)
        x = x_at(rect, t, t0, t1)
        pygame.draw.line(surf, REPLAY, (rect.x, y), (x, y), 4)
        pygame.draw.circle(surf, REPLAY, (x, y), 7)
        self.p.text("time", (rect.x - 3, y), draw.DIM, 16, "midright")


Line = tuple[np.ndarray, tuple[int, int, int], int]  # values, colour, width


def plot_ranges(shown: Replayed) -> list[tuple[float, float]]:
    """(low, high) of each plot: IR counts from 0, speeds and currents about 0; each fits its lines."""
    speeds = [shown.wheels] + ([shown.setpoints] if shown.setpoints is not None else [])
    v = max(50.0, max(float(np.abs(s).max()) for s in speeds))
    i = max(50.0, float(np.abs(shown.commands).max()))
    return [(0.0, max(100.0, float(shown.ir.max()))), (-v, v), (-i, i)]


def plot_lines(shown: Replayed) -> list[list[Line]]:
    """Each plot's lines, drawn in order: the 8 sensors; the set-points (thin, under) and the wheels' speeds
    from the encoders; the current references."""
    wheels: list[Line] = []
    if shown.setpoints is not None:
        wheels += [(shown.setpoints[:, 0], (150, 170, 230), 1), (shown.setpoints[:, 1], (240, 180, 130), 1)]
    wheels += [(shown.wheels[:, 0], LEFT, 2), (shown.wheels[:, 1], RIGHT, 2)]
    return [[(shown.ir[:, i], SENSOR_COLOURS[i], 1) for i in range(8)], wheels,
            [(shown.commands[:, 0], LEFT, 2), (shown.commands[:, 1], RIGHT, 2)]]


def _line(surf: pygame.Surface, r: pygame.Rect, t: np.ndarray, values: np.ndarray, lo: float, hi: float,
          colour: tuple[int, int, int], width: int, t0: float, t1: float) -> None:
    step = max(1, len(t) // (2 * r.width))
    tt, vv = t[::step], np.clip(values[::step], lo, hi)
    if len(tt) < 2:
        return
    xs = r.x + (tt - t0) / max(t1 - t0, 1e-9) * (r.width - 1)
    ys = r.bottom - 1 - (vv - lo) / (hi - lo) * (r.height - 2)
    pygame.draw.lines(surf, colour, False, np.column_stack([xs, ys]).tolist(), width)
