"""`twinbot gui`: the paper's application (§4, Fig. 14) — a room editor and three robots in one window.

Presentation only: drawing, events and layout.  The physics, the firmware
in the loop, the worlds, coverage and recordings are host_sim's, called
from here (tools/ may import host_sim; never the reverse).

- world_edit.py: the walls being edited (snap, pick, move, delete, undo, save, load)
- view.py: metres <-> pixels, zoom and pan
- user_input.py: keyboard and joystick events -> wheel-speed orders
- robots.py: the simulated robot and the user robot (firmware in SIL), the real robot (serial)
- app.py: the state and one frame; controls.py: keys, buttons, mouse; render.py + draw.py: drawing
- loop.py: the window's loop, headless runs and the frame-time benchmark
"""
import os

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # pygame's banner on import, before any module imports it
