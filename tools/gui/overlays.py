"""What makes the map readable: axes in metres, a scale bar, the cursor's coordinates, the rays' legend,
and each robot's sensors named (S1..S8) on its body with their counts beside them.

Drawn over the room by tools/gui/render.py with tools/gui/draw.py's Painter.  See docs/gui.md.
"""
from __future__ import annotations

import math
from typing import Sequence

import pygame

from host_sim.sensors.ir_sensor import BEARINGS
from tools.gui import draw
from tools.gui.view import Viewport

NICE_STEPS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0)
LABELS_MIN_PX = 40  # a body smaller than this on screen is marked 1..8 (S1..S8 would overlap)
DIGITS_MIN_PX = 16  # and below this not at all
COUNTS_MIN_PX = 10  # nor counts beside its sensors below this


def nice_step(scale: float, min_px: float) -> float:
    """The smallest round length (m) at least min_px pixels long at scale px/m."""
    return next((s for s in NICE_STEPS if s * scale >= min_px), NICE_STEPS[-1])


def axes(p: draw.Painter, view: Viewport) -> None:
    """Tick labels in metres along the room area's left and bottom edges, and the axes' names."""
    rx, ry, w, h = view.rect
    step = nice_step(view.scale, 70)
    x0, y0 = view.to_world(rx, ry + h)
    x1, y1 = view.to_world(rx + w, ry)
    for k in range(math.ceil(x0 / step), math.floor(x1 / step) + 1):
        sx = view.to_screen(k * step, 0)[0]
        pygame.draw.line(p.surface, draw.DIM, (sx, ry + h - 5), (sx, ry + h))
        p.text(f"{k * step:g}", (sx, ry + h - 6), draw.DIM, 16, "midbottom")
    for k in range(math.ceil(y0 / step), math.floor(y1 / step) + 1):
        sy = view.to_screen(0, k * step)[1]
        p.text(f"{k * step:g}", (rx + 3, sy), draw.DIM, 16, "midleft")
    p.text("x, m", (rx + w - 4, ry + h - 20), draw.DIM, 16, "bottomright")
    p.text("y, m", (rx + 4, ry + 4), draw.DIM, 16)


def scale_bar(p: draw.Painter, view: Viewport) -> None:
    """A bar of a round length at the room area's bottom left."""
    rx, ry, _w, h = view.rect
    length = nice_step(view.scale, 80)
    px = int(round(length * view.scale))
    x, y = rx + 40, ry + h - 36
    pygame.draw.line(p.surface, draw.TEXT, (x, y), (x + px, y), 3)
    for end in (x, x + px):
        pygame.draw.line(p.surface, draw.TEXT, (end, y - 5), (end, y + 5), 2)
    p.text(f"{length * 100:g} cm" if length < 1 else f"{length:g} m", (x + px // 2, y - 4), draw.TEXT, 16,
           "midbottom")


def cursor(p: draw.Painter, view: Viewport, screen_pos: tuple[int, int]) -> None:
    """The world coordinates under the mouse, at the room area's top right (only while it is over the room)."""
    if not view.contains(*screen_pos):
        return
    x, y = view.to_world(*screen_pos)
    rx, ry, w, _h = view.rect
    p.text(f"cursor ({x:.3f}, {y:.3f}) m", (rx + w - 6, ry + 4), draw.TEXT, 18, "topright")


def ray_legend(p: draw.Painter, view: Viewport, full_scale: float, sensor_range: float) -> None:
    """What a ray's shade and width mean: reflected counts, 0 .. the ADC's full scale; its length the range."""
    rx, ry, _w, _h = view.rect
    x, y, width = rx + 60, ry + 6, 120
    for i in range(width):
        strength = i / (width - 1)
        shade = tuple(int(255 - (255 - k) * (0.25 + 0.75 * strength)) for k in draw.COLOURS["simulated"])
        pygame.draw.line(p.surface, shade, (x + i, y + 4), (x + i, y + 4 + 1 + int(2 * strength) * 2))
    p.text("IR ray shade: counts", (x + width + 6, y), draw.DIM, 16)
    p.text("0", (x, y + 12), draw.DIM, 16)
    p.text(f"{full_scale:.0f}", (x + width, y + 12), draw.DIM, 16, "topright")
    p.text(f"rays end at the sensor's range, {100 * sensor_range:g} cm; sensors S1..S8 numbered on the body",
           (x + width + 6, y + 14), draw.DIM, 16)


def sensors(p: draw.Painter, view: Viewport, pose: tuple[float, float, float], radius: float,
            counts: Sequence[int], colour: tuple[int, int, int]) -> None:
    """S1..S8 on the body by their sensors and each one's count just outside the rim."""
    x, y, phi = pose
    r_px = radius * view.scale
    if r_px < COUNTS_MIN_PX:
        return
    for i, (bearing, count) in enumerate(zip(BEARINGS, counts)):
        c, s = math.cos(phi + bearing), math.sin(phi + bearing)
        if r_px >= DIGITS_MIN_PX:
            p.text(f"S{i + 1}" if r_px >= LABELS_MIN_PX else f"{i + 1}", view.to_screen(x + 0.68 * radius * c, y + 0.68 * radius * s), draw.TEXT, 16,
                   "center")
        out = radius + 13 / view.scale
        p.text(f"{count}", view.to_screen(x + out * c, y + out * s), colour, 16, "center")
