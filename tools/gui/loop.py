"""The window's loop: interactive (capped at 60 frames/s), headless for N frames, or timed.

Headless runs (--frames N) step by a nominal 1/60 s of wall time per frame,
not by the clock, so what they draw does not depend on the machine's speed:
N frames at speed k are N k / 60 simulated seconds.  See docs/gui.md.
"""
from __future__ import annotations

import os
import sys
import time

import pygame

from tools.gui.app import MIN_SIZE, App, Settings
from tools.gui.window import Window

FRAME_S = 1.0 / 60.0


def open_window(settings: Settings, headless: bool) -> Window:
    chosen = os.environ.get("SDL_VIDEODRIVER")
    if (not headless and not chosen and sys.platform.startswith("linux")
            and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))):
        raise pygame.error("no display: neither DISPLAY nor WAYLAND_DISPLAY is set")
    if headless:
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    pygame.display.init()
    if not headless and not chosen and pygame.display.get_driver() in ("offscreen", "dummy"):
        pygame.display.quit()  # SDL found no display and fell back to drawing nowhere: a window nobody sees
        raise pygame.error("no display found")
    pygame.font.init()
    pygame.joystick.init()
    size = (max(MIN_SIZE[0], settings.size[0]), max(MIN_SIZE[1], settings.size[1]))
    surface = pygame.display.set_mode(size, pygame.RESIZABLE)
    pygame.display.set_caption(f"twinbot gui - {settings.world.name}")
    return Window(App(settings, surface))


def run(window: Window, frames: int | None = None) -> int:
    """Run until the window closes (frames=None, paced by the clock) or for `frames` frames of 1/60 s."""
    clock = pygame.time.Clock()
    n = 0
    while not window.quit and (frames is None or n < frames):
        for event in pygame.event.get():
            window.handle(event)
        dt = clock.tick(60) / 1000.0 if frames is None else FRAME_S
        window.frame(dt)
        pygame.display.flip()
        n += 1
    return n


def time_frames(window: Window, frames: int, warmup: int = 30) -> list[float]:
    """Wall seconds of each frame's work (events, step, draw, flip), after `warmup` frames.

    Frames start every 1/60 s as in the window (the real robot's frames arrive
    at their own pace meanwhile); the wait for the next start is not counted.
    """
    times: list[float] = []
    start = time.perf_counter()
    for k in range(warmup + frames):
        t0 = time.perf_counter()
        for event in pygame.event.get():
            window.handle(event)
        window.frame(FRAME_S)
        pygame.display.flip()
        t1 = time.perf_counter()
        if k >= warmup:
            times.append(t1 - t0)
        wait = start + (k + 1) * FRAME_S - t1
        if wait > 0:
            time.sleep(wait)
    return times


def close() -> None:
    pygame.quit()
