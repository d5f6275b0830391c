"""What the window shows, laid out: the room on the left, a panel on the right, the status bar below.

`Renderer.draw()` draws the app's state and the controls' buttons and
previews with tools/gui/draw.py; what each part shows is in docs/gui.md.
"""
from __future__ import annotations

from typing import Sequence

import pygame

from protocol import messages as M
from tools.gui import draw
from tools.gui.app import App, replay_rect
from tools.gui import overlays, placing, replay_panel
from tools.gui.controls import Controls
from tools.gui.real_robot import RealBot
from tools.gui.robots import SimBot, rays

ADC_FULL = 4095.0
BAR_FULL = ADC_FULL  # counts at the top of a bar: readings reach the ADC's full scale


class Renderer:
    def __init__(self, app: App, controls: Controls) -> None:
        self.app = app
        self.controls = controls
        self.p = draw.Painter(app.surface)
        self._exit: tuple[object, tuple[float, float]] = (None, (0.0, 0.0))
        self._t90: tuple[object, int, float | None] = (None, 0, None)
        self.ghost_drawn: tuple[float, float, float] | None = None  # where the last frame drew the ghost
        self.bar_rects: dict[str, pygame.Rect] = {}  # each robot's IR bars in the panel
        self.replay = replay_panel.ReplayView(self.p)

    def draw(self) -> None:
        surf = self.p.surface = self.app.surface  # a new surface after a resize
        self.p.drawn.clear()
        surf.fill(draw.BG)
        self.room()
        if self.app.replay.open:
            self.replay.strip(pygame.Rect(replay_rect(surf.get_size())), self.app.replay)
        px = self.controls.panel_x
        pygame.draw.rect(surf, draw.PANEL, (px, 0, surf.get_width() - px, surf.get_height()))
        self.panel()
        self.status()
        if self.app.show_help:
            self.help()

    # -- the room -------------------------------------------------------------
    def room(self) -> None:
        app, p = self.app, self.p
        view, world = app.view, app.editor.world
        surf = app.surface
        surf.set_clip(pygame.Rect(view.rect))
        p.grid(view, app.editor.grid, world.size)
        cov = app.sim.sim.coverage
        if app.show_coverage:
            p.coverage(view, cov.covered, round(cov.fraction * cov.n_free), cov.resolution)
        p.walls(view, world.walls, app.editor.selected)
        preview = self.controls.preview()
        if preview is not None:
            p.preview(view, *preview)
        if self.controls.corners:
            p.corners(view, self.controls.corners, app.editor.snap(*self.controls.pointer))
        r = app.s.params.body_radius
        p.start(view, world.start, placing.start_handle(world.start, r), r, app.editor.start_blocked(r))
        bots: list[tuple[SimBot | RealBot, str]] = [(app.user, "user"), (app.sim, "simulated")]
        if app.real is not None:
            bots.insert(0, (app.real, "real"))
        for bot, name in bots:
            self.robot(bot, name)
        if app.replay.open:
            self.replay.room(view, app.replay, world, app.s.params)
        self.ghost_drawn = None
        if app.real is not None and app.show_ghost:
            self.ghost(app.real)
        if app.sim.sim.exit_time is not None:
            x, y = self.exit_point()
            p.flag(view, x, y)
        overlays.axes(p, view)
        overlays.scale_bar(p, view)
        overlays.ray_legend(p, view, BAR_FULL, app.s.params.sensor_range)
        overlays.cursor(p, view, self.controls.pointer_px)
        surf.set_clip(None)

    def exit_point(self) -> tuple[float, float]:
        """Where the simulated robot was when it left the room (found once per run)."""
        sim = self.app.sim.sim
        if self._exit[0] is not sim:
            i = next((k for k, t in enumerate(sim._t) if t >= sim.exit_time), -1)  # type: ignore[operator]  # noqa: SLF001
            self._exit = (sim, sim._pose[i][:2])  # noqa: SLF001
        return self._exit[1]  # type: ignore[return-value]

    def time_to_90(self) -> float | None:
        """The first control instant with coverage >= 90 %, scanning only the instants not seen yet."""
        cov = self.app.sim.sim.coverage
        seen_cov, seen, t90 = self._t90
        if seen_cov is not cov:
            seen, t90 = 0, None
        if t90 is None:
            fr = cov.fractions
            hit = next((k for k in range(seen, len(fr)) if fr[k] >= 0.9), None)
            t90 = self.app.sim.sim._t[hit] if hit is not None else None  # noqa: SLF001
            seen = len(fr)
        self._t90 = (cov, seen, t90)
        return t90

    def robot(self, bot: SimBot | RealBot, name: str) -> None:
        app, p = self.app, self.p
        colour = draw.COLOURS[name]
        pose = bot.pose
        p.trail(app.view, bot.trail, colour)
        p.rays(app.view, rays(app.editor.world, pose, app.s.params), bot.counts(), colour, BAR_FULL)
        contact = isinstance(bot, SimBot) and bot.sim.robot.in_contact
        p.robot(app.view, pose, app.s.params.body_radius, colour, contact)
        overlays.sensors(p, app.view, pose, app.s.params.body_radius, bot.counts(), colour)
        if isinstance(bot, SimBot):
            p.marks(app.view, bot.collision_marks, draw.RED)
        elif bot.crossings:  # where its odometry and the room disagree
            p.crossings(app.view, bot.crossings, "the real robot passed through a wall here: the twin stops at it")

    def ghost(self, real: RealBot) -> None:
        """The real robot's ghost over everything in the room, labelled with the link's lateness."""
        pose = real.ghost_pose()
        latency = real.ghost.latency_s
        if pose is None or latency is None:
            return
        label = f"ghost: now, {10 * round(100 * latency)} ms later"
        self.p.ghost(self.app.view, real.pose, pose, self.app.s.params.body_radius, label)
        self.ghost_drawn = pose

    # -- the panel ---------------------------------------------------------------
    def panel(self) -> None:
        app, p = self.app, self.p
        x = self.controls.panel_x + 10
        p.text(f"IR bars: reflected counts, 0 .. {BAR_FULL:.0f} (the ADC's full scale)", (x, 5), draw.DIM, 16)
        y = 22
        for bot, name in ((app.sim, "simulated"), (app.user, "user"), (app.real, "real")):
            self.robot_block(bot, name, x, y)
            y += 96
        cov = app.sim.sim.coverage
        t = app.sim.sim._t  # noqa: SLF001
        t90 = self.time_to_90()
        p.text(f"coverage of the simulated robot: {100 * cov.fraction:.1f} %", (x, y + 2), draw.TEXT, 20)
        p.plot(pygame.Rect(x + 22, y + 20, 338, 100), t, cov.fractions, t90)
        for rect, action in self.controls.buttons:
            on = bool(action.on and action.on())
            label = action.caption() if action.caption else action.label
            p.button(rect, label, on, rect.collidepoint(pygame.mouse.get_pos()))
        last = self.controls.buttons[-1][0]
        p.text("h: all keys and mouse controls", (x, last.bottom + 4), draw.DIM, 16)

    def robot_block(self, bot: SimBot | RealBot | None, name: str, x: int, y: int) -> None:
        p = self.p
        colour = draw.COLOURS[name]
        pygame.draw.circle(self.app.surface, colour, (x + 6, y + 8), 6)
        if bot is None:
            p.text(f"real robot: {self.app.real_error}", (x + 18, y), draw.DIM, 20)
            return
        p.text(self.robot_line(bot, name), (x + 18, y + 1), draw.TEXT, 18)
        self.bar_rects[name] = pygame.Rect(x, y + 22, 200, 54)
        p.bars(self.bar_rects[name], bot.counts(), colour, BAR_FULL)
        if isinstance(bot, SimBot):
            sp = bot.setpoints()
            rect = pygame.Rect(x + 212, y + 34, 148, 42)
            if sp is not None:
                p.text("wheel set-points, mm/s", (x + 212, y + 20), draw.DIM, 16)
                p.setpoints(rect, sp[0], sp[1], self.app.user_control.max_speed, colour)
            else:  # PIL, and TELEMETRY without set-points: the currents the firmware set
                p.text("current references, mA", (x + 212, y + 20), draw.DIM, 16)
                i_l, i_r = bot.currents()
                p.setpoints(rect, i_l, i_r, int(1000 * self.app.s.params.current_limit), colour)
        elif bot.lost is not None:
            p.text("LINK LOST: reconnecting", (x + 212, y + 24), draw.RED, 18)
            p.text(bot.lost[:34], (x + 212, y + 42), draw.RED, 16)
            p.text("walls and trail kept", (x + 212, y + 58), draw.DIM, 16)
        else:
            p.text(bot.source, (x + 212, y + 24), draw.DIM, 16)
            p.text(f"{bot.frames} TELEMETRY frames", (x + 212, y + 40), draw.DIM, 16)
            if bot.crossings:
                p.text(f"trail through {len(bot.crossings)} walls", (x + 212, y + 84), draw.RED, 16)
            latency = bot.ghost.latency_s
            if latency is not None:
                p.text(f"link late {1000 * latency:.0f} ms", (x + 212, y + 56), draw.GHOST, 16)
                p.text("(above its fastest frame)" if bot.ghost.floor_s == 0 else
                       f"(floor {1000 * bot.ghost.floor_s:.0f} ms)", (x + 212, y + 70), draw.DIM, 16)

    def robot_line(self, bot: SimBot | RealBot, name: str) -> str:
        x, y, phi = bot.pose
        where = f"({x:.2f}, {y:.2f}) m"
        if isinstance(bot, SimBot):
            m = bot.mode()
            mode = M.MODE_NAMES[m] if m is not None else "?"
            return f"{name}{' (PIL)' if bot.pil else ''}  {mode}  {where}  {bot.sim.robot.collisions} coll."
        mode = M.MODE_NAMES[int(bot.last["mode"])] if bot.last is not None else "?"  # type: ignore[call-overload]
        return f"real  {mode}  {where}  pose: odometry only"

    # -- status bar and help ---------------------------------------------------------
    def status(self) -> None:
        app, p = self.app, self.p
        surf = app.surface
        top = surf.get_height() - 40
        pygame.draw.rect(surf, (225, 227, 232), (0, top, surf.get_width(), 40))
        sim = app.sim.sim
        factor = app.clock.factor()
        rtf = f"{factor:.2f}x real time" if factor is not None else "-"
        fps = app.clock.fps()
        rtf += f"   {fps:.0f} fps" if fps is not None else ""
        exit_text = f"exit found at {sim.exit_time:.1f} s" if sim.exit_time is not None else "no exit yet"
        real = "real robot: " + (app.real_error if app.real is None else f"on {app.s.port}" if app.real.lost is None
                                 else f"LINK LOST on {app.s.port}, reconnecting")
        line1 = (f"t = {sim.robot.t:7.2f} s   {rtf}   speed {app.s.speed:g}x   "
                 f"{'real time (clock Dt)' if app.s.realtime else 'fixed step'}   "
                 f"{'RUNNING' if app.running else 'PAUSED'}   rules {app.s.rules}   L {app.s.emitter_pct} %   "
                 f"noise {'on' if app.s.noise else 'off'}   {exit_text}   {'REC' if app.recording else ''}")
        line2 = f"{real}   |   user: {app.user_control.device()}   |   {app.message}"
        p.text(line1, (8, top + 4), draw.TEXT, 20)
        p.text(line2, (8, top + 22), draw.DIM, 20)

    def help(self) -> None:
        lines: list[str] = ["twinbot gui: keys (buttons on the right do the same)", ""]
        lines += [f"{a.key_label}\t{a.help}" for a in self.controls.actions]
        lines += ["", *MOUSE_HELP]
        room = self.app.surface.get_height() - 20  # the lines closer together where the window is short
        pitch = max(14, min(19, (room - 24) // len(lines)))
        self.p.overlay(lines, pygame.Rect(60, 10, 780, pitch * len(lines) + 24), pitch)


MOUSE_HELP: Sequence[str] = (
    "arrows / joystick: drive the user robot (u: the simulated one too, i: the real one)",
    "mouse: drag on the floor draws a wall, snapped to the grid (o: box, or polygon: click corners, Enter);",
    "       drag a wall moves it;",
    "       right click deletes a wall; wheel zooms; middle drag or shift+drag pans",
    "replay panel (e): drag its slider or a plot; PgUp / PgDn: 1 s; Home / End; drop a recording on the window",
    "esc, q: quit (with unsaved walls: press twice)",
)
