"""The application's state and its robots: one frame of the world, and every setting the user changes.

`App.update(dt)` moves the world on by one frame (orders, physics, the real
robot's frames); tools/gui/window.py adds the controls and the drawing.
See docs/gui.md.
"""
from __future__ import annotations

import collections
import datetime
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import pygame

from host_sim.controller.hardware_io import RULE_SETS
from host_sim.physics.params import RobotParams
from host_sim.recordings.recording import RecordingWriter
from host_sim.physics.world import World, WorldError
from protocol import messages as M
from tools.gui import placing
from tools.gui.real_robot import RealBot
from tools.gui.replay import Replay
from tools.gui.robots import SimBot
from tools.gui.user_input import UserControl
from tools.gui.view import Viewport
from tools.gui.world_edit import WallEditor

SIZE = (1280, 720)  # the default window: fits a 1366 x 768 laptop screen with its title bar
MIN_SIZE = (960, 700)  # smaller, and the panel's buttons would not fit
PANEL_W = 380  # the panel on the right
STATUS_H = 40  # the status bar below
REPLAY_H = 250  # the replay panel, under the room while it is open
SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
TOOLS = ("wall", "box", "polygon")
MAX_CATCH_UP = 0.1  # s of wall time a fixed-step frame makes up at most: a slow frame must not snowball
MAX_SPEED = M.param_by_name("max_speed")[4]  # mm/s, the firmware's default wheel-speed limit


def room_rect(size: tuple[int, int], replay: bool = False) -> tuple[int, int, int, int]:
    """The room's area of a window this size: all but the panel, the status bar and the replay panel."""
    return (0, 0, size[0] - PANEL_W, size[1] - STATUS_H - (REPLAY_H if replay else 0))


def replay_rect(size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The replay panel's area (while it is open): under the room, as wide as it."""
    return (0, size[1] - STATUS_H - REPLAY_H, size[0] - PANEL_W, REPLAY_H)


@dataclass
class Settings:
    world: World
    params: RobotParams
    rules: str = "refined"
    port: str | None = None
    pil: bool = False  # the simulated robot's firmware on a virtual board (MicroPython) instead of in process
    speed: float = 1.0
    realtime: bool = False
    noise: bool = True
    emitter_pct: int = 60
    seed: int = 0
    world_file: Path = Path("world.json")  # where save and load go
    out_dir: Path = Path(".")  # recordings and screenshots
    grid: float = 0.05  # m, the snapping grid
    link_floor_s: float = 0.0  # the real robot's link: its fastest delivery (the ghost's latency floor)
    size: tuple[int, int] = SIZE  # the window's size at start, pixels
    replay: Path | None = None  # a recording to show in the replay panel at start


@dataclass
class Clock:
    """Simulated seconds against wall seconds over the last second: the real-time factor."""

    samples: collections.deque[tuple[float, float]] = field(default_factory=lambda: collections.deque(maxlen=240))

    def tick(self, sim_t: float) -> None:
        if self.samples and sim_t < self.samples[-1][1]:  # a reset: the simulated time starts again
            self.samples.clear()
        self.samples.append((time.perf_counter(), sim_t))

    def fps(self) -> float | None:
        """Frames per wall second over the last second (the samples are one a frame)."""
        if len(self.samples) < 2:
            return None
        (w0, _), (w1, _) = self.samples[0], self.samples[-1]
        return (len(self.samples) - 1) / (w1 - w0) if w1 > w0 else None

    def factor(self) -> float | None:
        if len(self.samples) < 2:
            return None
        (w0, s0), (w1, s1) = self.samples[0], self.samples[-1]
        while len(self.samples) > 2 and w1 - self.samples[0][0] > 1.0:
            self.samples.popleft()
        return (s1 - s0) / (w1 - w0) if w1 > w0 else None


class App:
    def __init__(self, settings: Settings, surface: pygame.Surface) -> None:
        self.s = settings
        self.surface = surface
        self.editor = WallEditor(settings.world, settings.grid)
        self.view = Viewport(room_rect(surface.get_size()))
        self.view.fit(*settings.world.size)
        self.user_control = UserControl(MAX_SPEED)
        self.running = True
        self.show_help = False
        self.show_coverage = True
        self.show_ghost = True  # the real robot's ghost (the late-signal twin) beside its raw late pose
        self.tool = "wall"  # what the mouse draws: "wall", "box" or "polygon"
        self.user_drives_sim = False
        self.user_drives_real = False
        self.stop_at_exit = True  # pause when the simulated robot leaves the room (as `sim --stop-at-exit`)
        self.quit_asked = False  # Esc or q pressed once with unsaved walls: a second press quits
        self.recording: list[Path] = []
        self.message = ""
        self.clock = Clock()
        self.real: RealBot | None = None
        self.real_error = "absent (start with --port PORT)"
        if settings.port:  # first: a bad port fails before a virtual board (--pil) is started
            self._open_real(settings.port)
        self._make_bots()
        self._world_version = self.editor.version
        self.saved_walls = [dict(w) for w in self.editor.walls]
        self.replay = Replay(settings.replay)
        if settings.replay is not None:
            self.open_replay(settings.replay)

    # -- robots -----------------------------------------------------------------
    def _make_bots(self) -> None:
        s, world = self.s, self.editor.world
        rule_set = RULE_SETS[s.rules]
        common = dict(seed=s.seed, noise=s.noise, emitter_pct=s.emitter_pct)
        for old in (getattr(self, "sim", None), getattr(self, "user", None)):
            if old is not None:
                old.close()
        self.sim = SimBot("simulated", world, s.params, rule_set, user=False, pil=s.pil, **common)  # type: ignore[arg-type]
        self.user = SimBot("user", world.with_changes(start=self.user_start()), s.params, rule_set, user=True,
                           **common)  # type: ignore[arg-type]
        self.user.set_world(world)

    def _open_real(self, port: str) -> None:
        from host_sim.board.serial_link import LinkError

        try:
            self.real = RealBot.open(port, self.editor.world.start, self.s.params, self.s.link_floor_s)
        except LinkError as exc:
            self.real_error = f"absent: {exc}"
            raise

    def user_start(self) -> placing.Pose:
        """Where the user's robot starts: beside the start, so that it hides neither the simulated robot nor
        the real one (those two start together there, to show where they part ways)."""
        return placing.beside(self.editor.world, self.editor.world.start, self.s.params.body_radius)

    def poses(self) -> dict[str, placing.Pose]:
        """Every robot's pose and the start's, by name (what the mouse may grab)."""
        out = {"simulated": self.sim.pose, "user": self.user.pose}
        if self.real is not None:
            out["real"] = self.real.pose
        return out | {"start": self.editor.world.start}

    def place(self, name: str, pose: placing.Pose) -> bool:
        """Put a robot or the start at pose (dragged or turned); False, nothing moved, where a wall is."""
        r = self.s.params.body_radius
        if name in ("simulated", "user") and not placing.clear_of_walls(self.editor.world, pose[0], pose[1], r):
            return False
        if name == "start":
            self.editor.set_start(pose)
            self.warn_start()
        elif name == "real" and self.real is not None:
            self.real.place(pose)
        else:
            (self.sim if name == "simulated" else self.user).place(pose)
        return True

    def warn_start(self) -> None:
        """Say so when a wall crosses the start: the robots' next reset would put them in it."""
        if self.editor.start_blocked(self.s.params.body_radius) and "crosses the start" not in self.message:
            self.say(f"{self.message}   WARNING: a wall crosses the start pose (drag its handle to move it)")

    @property
    def sim_bots(self) -> tuple[SimBot, SimBot]:
        return (self.sim, self.user)

    # -- one frame -----------------------------------------------------------------
    def update(self, dt: float) -> None:
        """One frame of dt wall seconds: orders, physics (if running), the real robot's frames.

        Fixed step: whole 40 ms periods worth dt x speed (dt capped at MAX_CATCH_UP); real time: the
        paper's clock loop with Dt = dt x speed (host_sim/loops/live.py)."""
        self.sync_world()
        orders = self.user_control.wheels()
        self.user.orders = orders
        self.sim.orders = orders if self.user_drives_sim else None
        if self.running:
            self.advance((dt if self.s.realtime else min(dt, MAX_CATCH_UP)) * self.s.speed)
        if self.real is not None:
            self.poll_real(orders)
        for bot in self.sim_bots:
            bot.after_frame()
        self.clock.tick(self.sim.sim.robot.t)
        self.replay.advance(dt, self.s.speed)
        verdict = self.replay.finished()
        if verdict is not None:
            self.say(verdict)

    def poll_real(self, orders: tuple[int, int]) -> None:
        """The real robot's frames; the link lost or back is said once, and the window runs on."""
        real = self.real
        assert real is not None
        real.orders = orders if self.user_drives_real else None
        real.world = self.editor.world
        was_lost = real.lost is not None
        real.poll()
        if real.lost is not None and not was_lost:
            self.user_drives_real = False
            self.say(f"real robot: link lost ({real.lost}); reconnecting to {real.port}, walls kept")
        elif real.lost is None and was_lost:
            self.say(f"real robot: link back on {real.port}")

    def sync_world(self) -> None:
        """The simulated robots move into the room as edited (before any step, and before drawing)."""
        if self.editor.version != self._world_version:
            for bot in self.sim_bots:
                bot.set_world(self.editor.world)
            self._world_version = self.editor.version
            self.warn_start()

    def advance(self, sim_seconds: float) -> None:
        """Fixed step: whole periods worth sim_seconds.  Real time: the frame's Dt in passes of at most
        one control period (the window's loop is slower than run_realtime's, whose passes are ~2 ms:
        one pass per frame at a high speed factor would skip control periods that run_realtime runs)."""
        self.sync_world()
        passes = max(1, math.ceil(sim_seconds / self.sim.sim.cycle_s - 1e-9))
        for bot in self.sim_bots:
            if bot is self.sim and self.stop_at_exit and bot.sim.exit_time is None:
                self._advance_to_exit(bot, sim_seconds, passes)
            elif self.s.realtime:
                for _ in range(passes):
                    bot.stepper.clock(sim_seconds / passes)
            else:
                bot.stepper.fixed(sim_seconds)

    def _advance_to_exit(self, bot: SimBot, sim_seconds: float, passes: int) -> None:
        """The simulated robot in passes of at most a period, paused in the period it leaves the room."""
        for _ in range(passes):
            if self.s.realtime:
                bot.stepper.clock(sim_seconds / passes)
            else:
                bot.stepper.fixed(sim_seconds / passes)
            if bot.sim.exit_time is not None:
                bot.stepper.owed = 0.0
                self.running = False
                self.say(f"the simulated robot found the exit at t = {bot.sim.exit_time:.2f} s: paused "
                         "(space runs on; x: stop at the exit off)")
                return

    def single_step(self) -> None:
        """One 40 ms control period of both simulated robots (pauses the run)."""
        self.running = False
        self.sync_world()
        for bot in self.sim_bots:
            bot.stepper.step_period()
        self.say(f"one step: t = {self.sim.sim.robot.t:.2f} s")

    def resize(self, surface: pygame.Surface) -> None:
        """The window was resized: the room's area follows, showing the same part of the room."""
        self.surface = surface
        x0, y0 = self.view.to_world(*self.view.rect[:2])
        self.view.rect = room_rect(surface.get_size(), self.replay.open)
        self.view.ox = x0
        self.view.oy = y0 - self.view.rect[3] / self.view.scale
        self.view.version += 1

    # -- settings the user changes -------------------------------------------------
    def say(self, text: str) -> None:
        self.message = text

    def toggle_run(self) -> None:
        self.running = not self.running
        self.say("running" if self.running else "paused")

    def change_speed(self, direction: int) -> None:
        k = min(range(len(SPEEDS)), key=lambda i: abs(SPEEDS[i] - self.s.speed))
        self.s.speed = SPEEDS[max(0, min(len(SPEEDS) - 1, k + direction))]
        self.say(f"speed {self.s.speed:g}x real time")

    def toggle_stop_at_exit(self) -> None:
        self.stop_at_exit = not self.stop_at_exit
        self.say("pause when the simulated robot finds the exit" if self.stop_at_exit
                 else "the simulated robot runs on past the exit")

    def toggle_view(self, name: str, what: str) -> None:
        """Show or hide one part of the room (show_coverage, show_ghost), and say which."""
        setattr(self, name, not getattr(self, name))
        self.say(f"{what} {'shown' if getattr(self, name) else 'hidden'}")

    def undo(self, redo: bool = False) -> None:
        done = self.editor.redo() if redo else self.editor.undo()
        verb = "redo" if redo else "undo"
        self.say(f"{verb}: {len(self.editor.walls)} walls now" if done else f"nothing to {verb}")

    def delete_selected(self) -> None:
        self.say("wall deleted (z undoes)" if self.editor.delete() else "nothing selected: click a wall first")

    @property
    def unsaved(self) -> bool:
        """The walls differ from the world file last saved or loaded (or from the start's room)."""
        return self.editor.walls != self.saved_walls

    def ask_quit(self) -> bool:
        """Esc or q: True to quit now; with unsaved walls only on the second press in a row."""
        if not self.unsaved or self.quit_asked:
            return True
        self.quit_asked = True
        self.say("the walls are not saved: press Esc or q again to quit without saving (s saves)")
        return False

    def toggle_realtime(self) -> None:
        self.s.realtime = not self.s.realtime
        self.say("real time: the step is the clock's Dt" if self.s.realtime else "fixed step: 40 ms / 8, repeatable")

    def toggle_noise(self) -> None:
        self.s.noise = not self.s.noise
        for bot in self.sim_bots:
            bot.set_noise(self.s.noise)
        self.say(f"sensor noise {'on' if self.s.noise else 'off'}")

    def toggle_rules(self) -> None:
        self.s.rules = "first" if self.s.rules == "refined" else "refined"
        self._set_param("rule_set", RULE_SETS[self.s.rules])
        self.say(f"rule set: {self.s.rules}")

    def change_emitter(self, delta: int) -> None:
        self.s.emitter_pct = max(0, min(100, self.s.emitter_pct + delta))
        self._set_param("emitter_pct", self.s.emitter_pct)
        self.say(f"emitter power L = {self.s.emitter_pct} %")

    def _set_param(self, name: str, value: int) -> None:
        for bot in self.sim_bots:
            bot.set_param(name, value)
        if self.real is not None:
            self.real.set_param(name, value)

    def next_tool(self) -> None:
        self.tool = TOOLS[(TOOLS.index(self.tool) + 1) % len(TOOLS)]
        self.say({"wall": "wall tool: drag on the floor draws a wall",
                  "box": "box tool: drag draws a rectangular obstacle",
                  "polygon": "polygon tool: click the corners, Enter closes (convex only)"}[self.tool])

    def toggle_user_drives_sim(self) -> None:
        self.user_drives_sim = not self.user_drives_sim
        self.say("the user's orders drive the simulated robot too (HOST mode)" if self.user_drives_sim
                 else "the simulated robot explores on its own (AUTONOMOUS)")

    def toggle_user_drives_real(self) -> None:
        if self.real is None:
            self.say("no real robot: start with --port PORT")
            return
        self.user_drives_real = not self.user_drives_real
        if not self.user_drives_real:
            self.real.release()
        self.say("the user's orders drive the real robot (HOST mode)" if self.user_drives_real
                 else "the real robot is released (STOP)")

    def real_mode(self, mode: int) -> None:
        """The real robot's AUTONOMOUS or STOP button: the mode now, and the user's orders no longer go to it."""
        if self.real is None:
            self.say("no real robot: start with --port PORT")
            return
        self.user_drives_real = False
        sent = self.real.set_mode(mode)
        self.say(f"real robot: {M.MODE_NAMES[mode]} sent" if sent else "real robot: link lost, nothing sent")

    def real_in_mode(self, mode: int) -> bool:
        """The real robot's last TELEMETRY says it is in this mode."""
        return self.real is not None and self.real.last is not None and int(self.real.last["mode"]) == mode  # type: ignore[call-overload]

    def reset(self) -> None:
        """Both simulated robots back at the room's start, fresh firmware; the real robot shown at the start."""
        if self.recording:
            self.toggle_record()
        self._make_bots()
        self._world_version = self.editor.version
        if self.real is not None:
            self.real.reset(self.editor.world.start)
        self.say("reset to the start pose")

    # -- replay and diagnosis ---------------------------------------------------------
    def open_replay(self, path: Path | None = None) -> None:
        """Show a recording in the replay panel: path, else the next one (the --replay file, then --out's)."""
        path = path or self.replay.next_file(self.s.out_dir)
        if path is None:
            self.say(f"replay: no recording in {self.s.out_dir} (record one with c, give --replay FILE, "
                     "or drop a file on the window)")
            return
        was_open = self.replay.open
        self.say(self.replay.load(Path(path), self.s.params, self.editor.world.start))
        if self.replay.open != was_open:
            self._fit_room()

    def close_replay(self) -> None:
        if self.replay.open:
            self.replay.close()
            self._fit_room()
            self.say("replay panel closed (e opens it again)")

    def _fit_room(self) -> None:
        """The replay panel opened or closed: the room's area changes, and the room is fitted in it."""
        self.view.rect = room_rect(self.surface.get_size(), self.replay.open)
        self.view.fit(*self.editor.world.size)

    def toggle_replay_play(self) -> None:
        if not self.replay.open:
            self.say("no recording to play: e loads one")
            return
        shown = self.replay.shown
        assert shown is not None
        if not self.replay.playing and self.replay.time >= shown.t[-1]:
            self.replay.seek(float(shown.t[0]))  # at the end: play again from the start
        self.replay.playing = not self.replay.playing
        self.say(f"replay {'playing' if self.replay.playing else 'paused'} at {self.s.speed:g}x")

    def scrub(self, seconds: float) -> None:
        """The slider seconds on (or back); +-inf: to an end."""
        self.replay.playing = False
        self.replay.seek(self.replay.time + seconds)

    def diagnose_replay(self) -> None:
        self.say(self.replay.diagnose())

    # -- files -------------------------------------------------------------------
    def toggle_record(self) -> None:
        """Start or stop recording each robot's trajectory, sensors and orders (docs/recordings.md)."""
        bots: list[SimBot | RealBot] = [*self.sim_bots, *([self.real] if self.real is not None else [])]
        if self.recording:
            for bot in bots:
                bot.record(None)
            self.say(f"recorded: {', '.join(str(p) for p in self.recording)}")
            self.recording = []
            return
        stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
        world, params = self.editor.world, self.s.params
        for bot, name in zip(bots, ("simulated", "user", "real")):
            path = self.s.out_dir / f"gui-{stamp}-{name}.csv"
            writer = RecordingWriter(path, source="robot" if name == "real" else "simulator", sample_period=0.04,
                                     robot=params.to_json(), world=world.to_dict(),
                                     extra={"controller": "SIL" if name != "real" else "serial", "which": name,
                                            "rules": self.s.rules, "noise": self.s.noise,
                                            "emitter_pct": self.s.emitter_pct})
            bot.record(writer)
            self.recording.append(path)
        self.say(f"recording {len(bots)} robots to {self.s.out_dir}/gui-{stamp}-*.csv")

    def screenshot(self, path: str | Path | None = None) -> Path:
        if path is None:
            path = self.s.out_dir / f"gui-{datetime.datetime.now().strftime('%Y%m%d-%H%M%S-%f')}.png"
        path = Path(path)
        pygame.image.save(self.surface, str(path))
        self.say(f"screenshot: {path}")
        return path

    def save_world(self) -> None:
        self.editor.save(self.s.world_file)
        self.saved_walls = [dict(w) for w in self.editor.walls]
        self.say(f"world saved: {self.s.world_file}")

    def load_world(self) -> None:
        try:
            self.editor.load(self.s.world_file, self.s.params.body_radius)
        except WorldError as exc:
            self.say(f"not loaded: {exc}")
            return
        self.view.fit(*self.editor.world.size)
        self.saved_walls = [dict(w) for w in self.editor.walls]
        self.reset()
        self.say(f"world loaded: {self.s.world_file}")

    def close(self) -> None:
        if self.recording:
            self.toggle_record()
        for bot in self.sim_bots:
            bot.close()
        if self.real is not None:
            self.real.close()
