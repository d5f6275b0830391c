"""One window: the application's state (app.py), its controls (controls.py) and its drawing (render.py).

`Window.frame(dt)` is one pass of the window's loop (tools/gui/loop.py):
the world moves on by dt, then everything is drawn.  See docs/gui.md.
"""
from __future__ import annotations

import pygame

from tools.gui.app import App
from tools.gui.controls import Controls
from tools.gui.render import Renderer


class Window:
    def __init__(self, app: App) -> None:
        self.app = app
        self.controls = Controls(app)
        self.renderer = Renderer(app, self.controls)
        self.frames = 0

    @property
    def quit(self) -> bool:
        """The user asked to close the window (Esc, q, or the window's close button)."""
        return self.controls.quit

    def handle(self, event: pygame.event.Event) -> None:
        self.controls.handle(event)

    def frame(self, dt: float) -> None:
        """One pass: the app's frame of dt wall seconds (orders, physics, the real robot), then drawing."""
        self.app.update(dt)
        self.renderer.draw()
        self.frames += 1
