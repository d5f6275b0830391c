"""`twinbot gui`: the paper's application (§4, Fig. 14) — a room editor and three robots in one window.

Presentation only (drawing, events, layout); the physics, firmware, worlds, coverage and recordings
are host_sim's.  Bottom up: world_edit, view, user_input, robots; app (the state, one frame of the
world); controls, draw, render; window (app + controls + drawing); loop.  See docs/gui.md.
"""
import os

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # pygame's banner on import, before any module imports it
