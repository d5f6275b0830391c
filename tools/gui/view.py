"""World metres <-> screen pixels: zoom about a point, pan, fit a room into a rectangle.

World frame: x right, y up (metres).  Screen: x right, y down (pixels).  See docs/gui.md.
"""
from __future__ import annotations

import numpy as np


class Viewport:
    def __init__(self, rect: tuple[int, int, int, int]) -> None:
        self.rect = rect  # x, y, w, h of the room's area on screen
        self.scale = 300.0  # pixels per metre
        self.ox = 0.0  # world x at the screen's left edge of rect
        self.oy = 0.0  # world y at the screen's bottom edge of rect
        self.version = 0  # bumped by every zoom or pan: caches key on it

    def fit(self, width: float, height: float, margin: float = 0.1) -> None:
        _x, _y, w, h = self.rect
        self.scale = min(w / (width + 2 * margin), h / (height + 2 * margin))
        self.ox = width / 2 - w / 2 / self.scale
        self.oy = height / 2 - h / 2 / self.scale
        self.version += 1

    def to_screen(self, x: float, y: float) -> tuple[int, int]:
        rx, ry, _w, h = self.rect
        return int(round(rx + (x - self.ox) * self.scale)), int(round(ry + h - (y - self.oy) * self.scale))

    def to_screen_array(self, xy: np.ndarray) -> np.ndarray:
        rx, ry, _w, h = self.rect
        out = np.empty_like(xy)
        out[:, 0] = rx + (xy[:, 0] - self.ox) * self.scale
        out[:, 1] = ry + h - (xy[:, 1] - self.oy) * self.scale
        return out

    def to_world(self, sx: float, sy: float) -> tuple[float, float]:
        rx, ry, _w, h = self.rect
        return self.ox + (sx - rx) / self.scale, self.oy + (ry + h - sy) / self.scale

    def zoom(self, factor: float, about: tuple[int, int]) -> None:
        """Zoom by factor keeping the world point under `about` (screen pixels) in place."""
        wx, wy = self.to_world(*about)
        self.scale = min(5000.0, max(20.0, self.scale * factor))
        rx, ry, _w, h = self.rect
        self.ox = wx - (about[0] - rx) / self.scale
        self.oy = wy - (ry + h - about[1]) / self.scale
        self.version += 1

    def pan(self, dx_px: float, dy_px: float) -> None:
        self.ox -= dx_px / self.scale
        self.oy += dy_px / self.scale
        self.version += 1

    def contains(self, sx: int, sy: int) -> bool:
        rx, ry, w, h = self.rect
        return rx <= sx < rx + w and ry <= sy < ry + h
