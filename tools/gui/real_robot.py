"""The real robot of the paper's application: a robot on a serial port, as the window sees it.

Its pose from its TELEMETRY odometry, its IR readings as they arrive, its ghost, its modes, and the
link: lost when the port goes away (a board killed, a Pico unplugged), reopened when it comes back.
See docs/gui.md.
"""
from __future__ import annotations

import math
import time

import numpy as np

from firmware.odometry import EXACT, HEADING_TURN, Odometry
from host_sim.board.serial_link import LinkError, SerialLink
from host_sim.controller.hardware_io import firmware_geometry
from host_sim.loops.late_signal_twin import Ghost
from host_sim.physics.params import RobotParams
from host_sim.physics.world import World
from host_sim.recordings.recording import RecordingWriter
from protocol import messages as M

Pose = tuple[float, float, float]
GHOST_HORIZON_S = 2.0  # the ghost runs on at most this long past the last frame: beyond, the signal is lost
RECONNECT_S = 1.0  # wall seconds between tries to reopen a lost port


def compose(base: Pose, rel: Pose) -> Pose:
    """rel (a pose in base's frame) in the world frame."""
    c, s = math.cos(base[2]), math.sin(base[2])
    return (base[0] + c * rel[0] - s * rel[1], base[1] + s * rel[0] + c * rel[1], base[2] + rel[2])


def relative(base: Pose, pose: Pose) -> Pose:
    """pose in base's frame (the inverse of compose)."""
    c, s = math.cos(base[2]), math.sin(base[2])
    dx, dy = pose[0] - base[0], pose[1] - base[1]
    return (c * dx + s * dy, -s * dx + c * dy, pose[2] - base[2])


class RealBot:
    """A robot on a serial port: pose from its TELEMETRY odometry, IR readings as they arrive, and its ghost.

    A Pico, or a virtual board's pty.  Its pose: odo_x, odo_y, odo_heading when the firmware sends
    them, else its encoders integrated here by the firmware's own odometry with the robot's geometry;
    placed at the room's start pose.  When the port fails (OSError, e.g. EIO) the link is marked lost
    and reopened every RECONNECT_S; the robot then goes on from where it was last shown.
    """

    def __init__(self, link: SerialLink, start: Pose, params: RobotParams, floor_s: float = 0.0,
                 port: str = "") -> None:
        self.link: SerialLink | None = link
        self.port = port
        self.params = params
        self.floor_s = floor_s
        self.start = start
        self.odo: Pose = (0.0, 0.0, 0.0)  # the robot's own odometry (its frame: where it started)
        self.anchor: Pose = (0.0, 0.0, 0.0)  # odometry pose that is shown at `start`
        self.source = "no TELEMETRY yet"
        self.trail: list[Pose] = []
        self.crossings: list[tuple[float, float]] = []  # where its trail passed through a wall of the room
        self.world: World | None = None  # the room the crossings are checked against
        self.ir_counts = [0] * 8
        self.last: dict[str, object] | None = None
        self.frames = 0
        self.orders: tuple[int, int] | None = None
        self.lost: str | None = None  # why the link was lost, while it is
        self.reconnects = 0
        self.recorder: RecordingWriter | None = None
        self._retry_at = 0.0
        self._rebase = False  # the next frame's odometry is shown at the robot's last pose
        self._fresh_link()

    def _fresh_link(self) -> None:
        """A new link's clock starts at 0: the ghost and the host's odometry start again with it."""
        diameter_um, base_um, ticks = firmware_geometry(self.params)
        self.ghost = Ghost(base_um / 1e6, diameter_um / 1e6, ticks, floor_s=self.floor_s)
        p = self.params
        self.odometry = Odometry(int(round(2e6 * p.wheel_radius)), int(round(2e6 * p.half_axle)),
                                 int(round(p.ticks_per_rev)), EXACT)
        self.last_rx = -math.inf  # link clock, s
        self._last_order = -math.inf

    @classmethod
    def open(cls, port: str, start: Pose, params: RobotParams, floor_s: float = 0.0) -> RealBot:
        return cls(SerialLink.open(port), start, params, floor_s, port)

    @property
    def pose(self) -> Pose:
        """The raw pose: where the robot was when it sent its last frame."""
        return compose(self.start, relative(self.anchor, self.odo))

    def ghost_pose(self) -> Pose | None:
        """Where the ghost says the robot is now (placed like `pose`); None before the first frame or while lost."""
        if self.link is None:
            return None
        now = min(self.link.now(), self.last_rx + GHOST_HORIZON_S)
        odo = self.ghost.predict(now)
        return None if odo is None else compose(self.start, relative(self.anchor, odo))

    def reset(self, start: Pose) -> None:
        """Show the robot at `start` from here on (its odometry goes on counting)."""
        self.place(start)
        self.trail.clear()
        self.crossings.clear()

    def place(self, pose: Pose) -> None:
        """Show the robot at `pose` now (dragged by the user): its odometry goes on from there."""
        self.start = pose
        self.anchor = self.odo

    # -- the link -------------------------------------------------------------------
    def poll(self) -> int:
        """Take the frames that have arrived (never waits); returns how many TELEMETRY.

        A failing port marks the link lost instead of raising; a lost one is reopened when it comes back."""
        if self.link is None:
            self._reconnect()
            return 0
        n = 0
        try:
            frames = self.link.poll(0.0)
        except OSError as exc:  # EIO from a pty whose board died, or an unplugged USB port
            self._lose(exc)
            return 0
        for frame in frames:
            if frame.msg_type == M.TELEMETRY:
                self.telemetry(frame.fields)
                self.last_rx = frame.t
                self.ghost.on_telemetry(self._ghost_frame(frame.fields), frame.t)
                n += 1
        self._send_orders()
        return n

    def _lose(self, exc: OSError) -> None:
        link, self.link = self.link, None
        self.lost = str(exc) or type(exc).__name__
        self._retry_at = time.monotonic() + RECONNECT_S
        try:
            if link is not None:
                link.close()
        except OSError:
            pass

    def _reconnect(self) -> None:
        if time.monotonic() < self._retry_at or not self.port:
            return
        self._retry_at = time.monotonic() + RECONNECT_S
        try:
            self.link = SerialLink.open(self.port)
        except (LinkError, OSError) as exc:
            self.lost = str(exc)
            return
        self.lost = None
        self.reconnects += 1
        self._fresh_link()
        self.place(self.pose)  # the robot may have restarted its odometry: go on from where it was shown
        self._rebase = True

    def _send(self, msg_type: int, fields: dict[str, object]) -> float | None:
        """Send if the link is up; the send time on the link's clock, or None (lost, or lost now)."""
        if self.link is None:
            return None
        try:
            return self.link.send(msg_type, fields).t
        except OSError as exc:
            self._lose(exc)
            return None

    # -- its frames -------------------------------------------------------------------
    def telemetry(self, f: dict[str, object]) -> None:
        self.frames += 1
        self.last = f
        on, amb = list(f["ir_on"]), list(f["ir_amb"])  # type: ignore[call-overload]
        self.ir_counts = [max(0, int(a) - int(b)) for a, b in zip(on, amb)]
        if "odo_heading" in f:
            self.odo = (int(f["odo_x"]) / 1e6, int(f["odo_y"]) / 1e6,  # type: ignore[call-overload]
                        2 * math.pi * int(f["odo_heading"]) / HEADING_TURN)  # type: ignore[call-overload]
            self.source = "TELEMETRY odometry"
        else:
            o = self.odometry
            o.update(int(f["enc_l"]), int(f["enc_r"]))  # type: ignore[call-overload]
            self.odo = (o.x_um / 1e6, o.y_um / 1e6, 2 * math.pi * o.heading / HEADING_TURN)
            self.source = "encoders integrated on the host"
        if self._rebase:  # the first frame after a reconnect: shown where it was
            self.anchor = self.odo
            self._rebase = False
        self._extend_trail(self.pose)
        if self.recorder is not None:
            self.recorder.telemetry(f)

    def _extend_trail(self, pose: Pose) -> None:
        """The trail, and where its last step crossed a wall that would have stopped the twin."""
        if self.trail and self.world is not None and self.world.n_walls:
            a = self.trail[-1]
            if not bool(self.world.visible(np.array([a[:2]]), np.array(pose[:2]))[0]):
                self.crossings.append(((a[0] + pose[0]) / 2, (a[1] + pose[1]) / 2))
        self.trail.append(pose)

    def _ghost_frame(self, f: dict[str, object]) -> dict[str, object]:
        """The frame as the ghost needs it: the odometry shown (the host's when the firmware sends none)."""
        if "odo_heading" in f and "sp_l" in f:
            return f
        g = dict(f)
        g.setdefault("sp_l", 0)
        g.setdefault("sp_r", 0)
        if "odo_heading" not in g:
            o = self.odometry
            g.update(odo_x=o.x_um, odo_y=o.y_um, odo_heading=o.heading)
        return g

    # -- orders -----------------------------------------------------------------------
    def _send_orders(self) -> None:
        """HOST-mode orders at 10 Hz while the user drives it (its watchdog stops it 200 ms after they end)."""
        if self.link is None:
            return
        now = self.link.now()
        if self.orders is not None and now - self._last_order >= 0.1:
            t = self._send(M.COMMAND, {"mode": M.MODE_HOST, "left": self.orders[0], "right": self.orders[1]})
            if t is not None:
                self.ghost.on_command(t, *self.orders)
                self.ghost.forget_before(t - 5.0)
            self._last_order = now

    def release(self) -> None:
        """The user lets go: stop the robot now rather than at its watchdog."""
        self.set_mode(M.MODE_STOP)

    def set_mode(self, mode: int) -> bool:
        """STOP or AUTONOMOUS now (the user's orders no longer go to it); False if the link is lost."""
        self.orders = None
        t = self._send(M.COMMAND, {"mode": mode, "left": 0, "right": 0})
        if t is not None and mode == M.MODE_STOP:
            self.ghost.on_command(t, 0, 0)  # STOP: the wheels' set-points are zero from now on
        return t is not None

    def set_param(self, name: str, value: int) -> None:
        self._send(M.PARAM_SET, {"param": M.param_by_name(name)[0], "value": int(value)})

    def counts(self) -> list[int]:
        return self.ir_counts

    def record(self, writer: RecordingWriter | None) -> None:
        if self.recorder is not None and writer is None:
            self.recorder.close()
        self.recorder = writer

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()
        if self.link is not None:
            try:
                self.link.close()
            except OSError:
                pass
