"""Keys, buttons and the mouse: every control is one `Action`, reachable by a key and most by a button.

The mouse edits the room with the current drawing tool (wall, box, convex
polygon), selects, moves and deletes walls, zooms and pans.  Every key and
mouse gesture is listed in docs/gui.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import pygame

from protocol import messages as M
from pathlib import Path

from tools.gui import placing, replay_panel
from tools.gui.app import MIN_SIZE, PANEL_W, App, replay_rect
from tools.gui.replay import SCRUB_STEP_S

BUTTON_TOP = 462  # the panel's robots and coverage plot are above
BUTTON_SIZE = (70, 24)
BUTTON_COLUMNS = 5
PICK_PX = 7  # a wall within this many pixels of the cursor is under it
TURN_STEP = math.radians(15)  # one notch of the wheel over a robot or the start's handle turns it this much
SCRUB_KEYS = {pygame.K_PAGEUP: -SCRUB_STEP_S, pygame.K_PAGEDOWN: SCRUB_STEP_S, pygame.K_HOME: -math.inf,
              pygame.K_END: math.inf}  # the replay panel's slider


@dataclass
class Action:
    keys: tuple[int, ...]
    key_label: str
    label: str  # button text ("" = key only)
    help: str
    do: Callable[[], Any]
    on: Callable[[], bool] | None = None  # lit button when true
    caption: Callable[[], str] | None = None  # the button's text when it changes with the state


def actions(app: App, controls: Controls) -> list[Action]:
    k = pygame
    return [
        Action((k.K_SPACE,), "space", "run/pause", "run / pause", app.toggle_run, lambda: app.running),
        Action((k.K_PERIOD,), ".", "step", "one 40 ms control period (pauses)", app.single_step),
        Action((k.K_MINUS, k.K_KP_MINUS), "-", "slower", "speed factor down", lambda: app.change_speed(-1)),
        Action((k.K_EQUALS, k.K_PLUS, k.K_KP_PLUS), "+", "faster", "speed factor up", lambda: app.change_speed(1)),
        Action((k.K_t,), "t", "real time", "real time (step = clock Dt) / fixed step", app.toggle_realtime,
               lambda: app.s.realtime),
        Action((k.K_n,), "n", "noise", "sensor noise on / off", app.toggle_noise, lambda: app.s.noise),
        Action((k.K_f,), "f", "rules", "rule set: first / refined", app.toggle_rules,
               lambda: app.s.rules == "refined"),
        Action((k.K_LEFTBRACKET,), "[", "L -10", "emitter power L down 10 %", lambda: app.change_emitter(-10)),
        Action((k.K_RIGHTBRACKET,), "]", "L +10", "emitter power L up 10 %", lambda: app.change_emitter(10)),
        Action((k.K_r,), "r", "reset", "reset the robots to the start", app.reset),
        Action((k.K_c,), "c", "record", "record all robots (CSV + JSON, docs/recordings.md)", app.toggle_record,
               lambda: bool(app.recording)),
        Action((k.K_p, k.K_F12), "p", "screenshot", "screenshot (PNG)", lambda: app.screenshot()),
        Action((k.K_u,), "u", "user->sim", "the user's orders drive the simulated robot too", app.toggle_user_drives_sim,
               lambda: app.user_drives_sim),
        Action((k.K_i,), "i", "user->real", "the user's orders drive the real robot too", app.toggle_user_drives_real,
               lambda: app.user_drives_real),
        Action((k.K_a,), "a", "real: auto", "the real robot explores on its own (AUTONOMOUS)",
               lambda: app.real_mode(M.MODE_AUTONOMOUS), lambda: app.real_in_mode(M.MODE_AUTONOMOUS)),
        Action((k.K_b,), "b", "real: STOP", "the real robot stops (STOP mode)", lambda: app.real_mode(M.MODE_STOP),
               lambda: app.real_in_mode(M.MODE_STOP)),
        Action((k.K_v,), "v", "coverage", "coverage overlay on / off",
               lambda: app.toggle_view("show_coverage", "coverage overlay"), lambda: app.show_coverage),
        Action((k.K_g,), "g", "ghost", "the real robot's ghost (where it is now, its signal being late) on / off",
               lambda: app.toggle_view("show_ghost", "the real robot's ghost"), lambda: app.show_ghost),
        Action((k.K_x,), "x", "stop@exit", "pause when the simulated robot finds the exit (as sim --stop-at-exit)",
               app.toggle_stop_at_exit, lambda: app.stop_at_exit),
        Action((k.K_o,), "o", "tool", "drawing tool: wall / box / convex polygon", controls.next_tool,
               lambda: app.tool != "wall", lambda: f"{app.tool}"),
        Action((k.K_s,), "s", "save", "save the world file", app.save_world),
        Action((k.K_l,), "l", "load", "load the world file", app.load_world),
        Action((k.K_z,), "z", "undo", "undo the last change to the walls", app.undo),
        Action((k.K_y,), "ctrl+y", "redo", "redo what undo took back (also shift+ctrl+z)", lambda: app.undo(redo=True)),
        Action((k.K_DELETE, k.K_BACKSPACE), "del", "delete", "delete the selected wall", app.delete_selected),
        Action((k.K_0,), "0", "fit", "fit the room in the view", lambda: app.view.fit(*app.editor.world.size)),
        Action((k.K_e,), "e", "replay", "replay a recording: the --replay file, then the next in --out (or drop one here)",
               lambda: app.open_replay(), lambda: app.replay.open),
        Action((k.K_j,), "j", "play rec", "play / pause the recording in the replay panel", app.toggle_replay_play,
               lambda: app.replay.playing),
        Action((k.K_d,), "d", "diagnose", "diagnose the recording in the replay panel (in the background)",
               app.diagnose_replay, lambda: app.replay.job is not None and app.replay.job.running),
        Action((k.K_k,), "k", "", "close the replay panel (or its x)", app.close_replay),
        Action((k.K_h,), "h", "help", "this help", app_toggle(app, "show_help"), lambda: app.show_help),
    ]


def app_toggle(app: App, name: str) -> Callable[[], None]:
    def flip() -> None:
        setattr(app, name, not getattr(app, name))

    return flip


class Controls:
    def __init__(self, app: App) -> None:
        self.app = app
        self.actions = actions(app, self)
        self.by_key = {key: a for a in self.actions for key in a.keys}
        self.buttons: list[tuple[pygame.Rect, Action]] = []
        self.layout()
        self.drag: tuple[Any, ...] | None = None  # ("draw", a, b) | ("move", i, wall, start) | ("pan", pos)
        self.corners: list[tuple[float, float]] = []  # the polygon being drawn
        self.pointer = (0.0, 0.0)  # world point under the mouse
        self.pointer_px = (-1, -1)  # the mouse on screen (off the window until it moves)
        self.quit = False

    @property
    def panel_x(self) -> int:
        return self.app.surface.get_width() - PANEL_W

    def layout(self) -> None:
        """The buttons in the panel, in rows of BUTTON_COLUMNS, wherever the panel is now."""
        self.buttons = []
        for i, a in enumerate(x for x in self.actions if x.label):
            col, row = i % BUTTON_COLUMNS, i // BUTTON_COLUMNS
            rect = pygame.Rect(self.panel_x + 10 + col * (BUTTON_SIZE[0] + 3), BUTTON_TOP + row * (BUTTON_SIZE[1] + 3),
                               *BUTTON_SIZE)
            self.buttons.append((rect, a))

    def resize(self, width: int, height: int) -> None:
        """The window's new size (at least MIN_SIZE): the room's area, the panel and its buttons follow."""
        size = (max(MIN_SIZE[0], width), max(MIN_SIZE[1], height))
        surface = pygame.display.get_surface()
        if surface is None or surface.get_size() != size:  # SDL resized it already, unless under the minimum
            surface = pygame.display.set_mode(size, pygame.RESIZABLE)
        self.app.resize(surface)
        self.layout()

    def next_tool(self) -> None:
        """The next drawing tool; a polygon's corners clicked so far are dropped."""
        self.app.next_tool()
        self.corners = []

    def handle(self, event: pygame.event.Event) -> None:
        app = self.app
        if app.user_control.handle(event):
            return
        if event.type == pygame.QUIT:
            self.quit = app.ask_quit()
        elif event.type == pygame.VIDEORESIZE:
            self.resize(event.w, event.h)
        elif event.type == pygame.KEYDOWN:
            self.key(event)
        elif event.type == pygame.MOUSEBUTTONDOWN:
            self.press(event.pos, event.button)
        elif event.type == pygame.MOUSEMOTION:
            self.motion(event.pos, event.rel)
        elif event.type == pygame.MOUSEBUTTONUP:
            self.release(event.pos, event.button)
        elif event.type == pygame.DROPFILE:  # a file dropped on the window: a recording to replay
            app.open_replay(Path(event.file))
        elif event.type == pygame.MOUSEWHEEL:
            pos = pygame.mouse.get_pos()
            if app.view.contains(*pos):
                self.wheel(pos, event.y)

    def key(self, event: pygame.event.Event) -> None:
        if self.corners and event.key in (pygame.K_RETURN, pygame.K_KP_ENTER, pygame.K_BACKSPACE, pygame.K_ESCAPE):
            self.polygon_key(event.key)
            return
        if event.key in (pygame.K_ESCAPE, pygame.K_q):
            self.quit = self.app.ask_quit()
            return
        self.app.quit_asked = False  # any other key: a later Esc asks again
        mods = getattr(event, "mod", 0)
        if event.key == pygame.K_z and mods & pygame.KMOD_CTRL and mods & pygame.KMOD_SHIFT:
            self.app.undo(redo=True)
            return
        if event.key in SCRUB_KEYS:
            self.app.scrub(SCRUB_KEYS[event.key])
            return
        action = self.by_key.get(event.key)
        if action is not None:
            action.do()

    def press(self, pos: tuple[int, int], button: int) -> None:
        app = self.app
        for rect, action in self.buttons:
            if rect.collidepoint(pos) and button == 1:
                action.do()
                return
        if app.replay.open and pygame.Rect(replay_rect(app.surface.get_size())).collidepoint(pos):
            self.press_replay(pos, button)
            return
        if not app.view.contains(*pos):
            return
        world_pt = app.view.to_world(*pos)
        shift = bool(pygame.key.get_mods() & pygame.KMOD_SHIFT)
        if button == 2 or (button == 1 and shift):
            self.drag = ("pan", pos)
            return
        grabbed = self.robot_at(pos) if button == 1 and app.tool != "polygon" else None
        if grabbed is not None:  # a robot or the start: dragging it moves it, never draws a wall
            x, y, _phi = app.poses()[grabbed]
            self.drag = ("robot", grabbed, (world_pt[0] - x, world_pt[1] - y))
            return
        picked = app.editor.pick(*world_pt, PICK_PX / app.view.scale)
        if button == 3:
            if picked is not None:
                app.editor.delete(picked)
                app.say("wall deleted")
            return
        if button != 1:
            return
        if app.tool == "polygon":
            self.corners.append(app.editor.snap(*world_pt))
            return
        if picked is not None:
            app.editor.selected = picked
            app.editor.begin_move()
            self.drag = ("move", picked, dict(app.editor.walls[picked]), world_pt, app.editor.version)
        else:
            app.editor.selected = None
            start = app.editor.snap(*world_pt)
            self.drag = ("box" if app.tool == "box" else "draw", start, start)

    def press_replay(self, pos: tuple[int, int], button: int) -> None:
        """On the replay panel: its x closes it; elsewhere a press (and a drag) puts the slider there."""
        strip = pygame.Rect(replay_rect(self.app.surface.get_size()))
        if button != 1:
            return
        if replay_panel.close_box(strip).collidepoint(pos):
            self.app.close_replay()
            return
        self.drag = ("scrub",)
        self.scrub_to(pos[0])

    def scrub_to(self, x: int) -> None:
        shown = self.app.replay.shown
        if shown is not None:
            self.app.replay.playing = False
            strip = pygame.Rect(replay_rect(self.app.surface.get_size()))
            self.app.replay.seek(replay_panel.time_at(strip, x, float(shown.t[0]), float(shown.t[-1])))

    def wheel(self, pos: tuple[int, int], notches: int) -> None:
        """Over a robot or the start's handle: turn it; elsewhere: zoom about the cursor."""
        app = self.app
        name = self.robot_at(pos)
        if name is None:
            app.view.zoom(1.15 ** notches, pos)
            return
        x, y, phi = app.poses()[name]
        if app.place(name, (x, y, phi + notches * TURN_STEP)):
            app.say(f"{name} turned to {math.degrees(phi + notches * TURN_STEP) % 360:.0f} deg")

    def robot_at(self, pos: tuple[int, int]) -> str | None:
        """The robot under the cursor (the one drawn on top first), or "start" on the start's handle."""
        app = self.app
        x, y = app.view.to_world(*pos)
        r = app.s.params.body_radius
        poses = app.poses()
        hx, hy = placing.start_handle(poses["start"], r)
        if math.hypot(x - hx, y - hy) <= max(r / 2, PICK_PX / app.view.scale):
            return "start"
        for name in ("simulated", "user", "real"):
            if name in poses and math.hypot(x - poses[name][0], y - poses[name][1]) <= r:
                return name
        return None

    def polygon_key(self, k: int) -> None:
        app = self.app
        if k == pygame.K_BACKSPACE:
            self.corners.pop()
        elif k == pygame.K_ESCAPE:
            self.corners = []
        else:
            error = app.editor.add_polygon(self.corners)
            app.say(error or f"obstacle {len(app.editor.walls) - 1}: polygon of {len(self.corners)} corners")
            if error is None:
                self.corners = []

    def motion(self, pos: tuple[int, int], rel: tuple[int, int]) -> None:
        app, drag = self.app, self.drag
        self.pointer = app.view.to_world(*pos)
        self.pointer_px = pos
        if drag is None:
            return
        if drag[0] == "scrub":
            self.scrub_to(pos[0])
        elif drag[0] == "pan":
            app.view.pan(pos[0] - drag[1][0], pos[1] - drag[1][1])
            self.drag = ("pan", pos)
        elif drag[0] in ("draw", "box"):
            self.drag = (drag[0], drag[1], app.editor.snap(*app.view.to_world(*pos)))
        elif drag[0] == "move":
            x, y = app.view.to_world(*pos)
            app.editor.move_to(drag[1], drag[2], x - drag[3][0], y - drag[3][1])
        elif drag[0] == "robot":
            x, y = self.pointer
            phi = app.poses()[drag[1]][2]
            app.place(drag[1], (x - drag[2][0], y - drag[2][1], phi))

    def release(self, pos: tuple[int, int], button: int) -> None:
        app, drag = self.app, self.drag
        self.drag = None
        if drag is None:
            return
        if drag[0] == "draw" and button == 1:
            end = app.editor.snap(*app.view.to_world(*pos))
            if app.editor.add_segment(drag[1], end):
                app.say(f"wall {len(app.editor.walls) - 1}: {drag[1]} -> {end}")
        elif drag[0] == "box" and button == 1:
            end = app.editor.snap(*app.view.to_world(*pos))
            r = app.s.params.body_radius
            under = [n for n, (x, y, _) in app.poses().items() if n != "start" and placing.box_covers(drag[1], end, x, y, r)]
            if under:
                app.say(f"no box over a robot: it would cover the {', '.join(under)} robot (drag the robot away first)")
            elif app.editor.add_box(drag[1], end):
                app.say(f"obstacle {len(app.editor.walls) - 1}: box {drag[1]} - {end}")
        elif drag[0] == "move" and app.editor.version == drag[4]:
            app.editor.drop_undo()  # a click that selected without moving: nothing to undo
        elif drag[0] == "robot":
            x, y, phi = app.poses()[drag[1]]
            app.say(f"{drag[1]}{' pose' if drag[1] == 'start' else ' robot'} at ({x:.2f}, {y:.2f}) m, "
                    f"{math.degrees(phi) % 360:.0f} deg (the wheel over it turns it)")
            app.warn_start()

    def preview(self) -> tuple[str, tuple[float, float], tuple[float, float]] | None:
        """The wall or box being drawn: (kind, a, b)."""
        if self.drag is not None and self.drag[0] in ("draw", "box") and self.drag[1] != self.drag[2]:
            return self.drag[0], self.drag[1], self.drag[2]
        return None
