"""The three robots of the paper's application (§4, Fig. 14), as the window sees them.

`SimBot`: the simulated robot (AUTONOMOUS, the fuzzy explorer) and the user robot (HOST, the user's
orders), each running the firmware itself; `RealBot`: a robot on a serial port.  See docs/gui.md.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from firmware.odometry import EXACT, HEADING_TURN, Odometry
from host_sim.loops.late_signal_twin import Ghost
from host_sim.controller.hardware_io import firmware_geometry
from host_sim.sensors.ir_sensor import BEARINGS
from host_sim.loops.live import LiveStepper
from host_sim.physics.params import RobotParams
from host_sim.board.pil import PilController
from host_sim.recordings.recording import RecordingWriter
from host_sim.board.serial_link import SerialLink
from host_sim.controller.sil import SilController
from host_sim.loops.simulation import Simulation
from host_sim.physics.world import World
from protocol import messages as M
from protocol.framing import FrameEncoder

Pose = tuple[float, float, float]


def rays(world: World, pose: Pose, params: RobotParams) -> np.ndarray:
    """The eight IR rays: (8, 4) rows x0, y0 (on the body's rim), x1, y1 (the wall hit, or the range's end)."""
    x, y, phi = pose
    r = params.body_radius
    reach = params.sensor_range + r
    if world.n_walls:
        dist, _angle, _hit = world.cast_robot(x, y, phi, BEARINGS, reach)
        d = np.minimum(np.nan_to_num(dist, nan=reach, posinf=reach), reach)
    else:
        d = np.full(len(BEARINGS), reach)
    ang = phi + np.asarray(BEARINGS)
    c, s = np.cos(ang), np.sin(ang)
    return np.stack([x + r * c, y + r * s, x + d * c, y + d * s], 1)


class SimBot:
    """A SimRobot with the firmware in SIL, stepped a frame at a time.

    The controller is the firmware in this process (SilController), or for the simulated robot with
    --pil on a virtual board under MicroPython (PilController: its mode and set-points then known from
    its TELEMETRY only).  When the user's orders are routed to the simulated robot it is switched to
    HOST mode, and back to AUTONOMOUS when they are taken away.  Orders go as COMMAND frames just
    before each control cycle, so they feed the firmware's watchdog whatever the speed factor.
    """

    def __init__(self, name: str, world: World, params: RobotParams, rule_set: int, *, seed: int, noise: bool,
                 emitter_pct: int, user: bool, pil: bool = False) -> None:
        self.name = name
        self.params = params
        self.seed = seed
        self.user = user  # the user robot: always HOST mode
        self.pil = pil
        self.controller: Any = PilController(rule_set) if pil else SilController(rule_set)
        self.encoder = FrameEncoder()
        self._host = False  # the last mode sent was HOST
        self.last_telemetry: dict[str, object] | None = None
        self.sim = Simulation(world, params, self.controller, seed=seed, noise=noise)
        self.stepper = LiveStepper(self.sim, self._before_control)
        self.orders: tuple[int, int] | None = (0, 0) if user else None  # HOST wheel speeds, mm/s
        self.set_param("emitter_pct", emitter_pct)
        self.collision_marks: list[tuple[float, float]] = []
        self._collisions_seen = 0
        self.recorder: RecordingWriter | None = None

    # -- orders to the firmware ---------------------------------------
    def _send(self, msg_type: int, fields: dict[str, object]) -> None:
        self.controller.send(self.encoder.encode(msg_type, M.pack_payload(msg_type, fields)))  # type: ignore[arg-type]

    def _before_control(self) -> None:
        if self.orders is not None:
            self._send(M.COMMAND, {"mode": M.MODE_HOST, "left": self.orders[0], "right": self.orders[1]})
            self._host = True
        elif self._host:  # the user let go: back to exploring
            self._send(M.COMMAND, {"mode": M.MODE_AUTONOMOUS, "left": 0, "right": 0})
            self._host = False

    def set_param(self, name: str, value: int) -> None:
        self._send(M.PARAM_SET, {"param": M.param_by_name(name)[0], "value": int(value)})

    def set_noise(self, on: bool) -> None:
        self.sim.robot.rng = np.random.default_rng(self.seed) if on else None

    def set_world(self, world: World) -> None:
        """The room was edited: the robot stays where it is; coverage is recounted over its trail."""
        from host_sim.loops.coverage import Coverage

        sim = self.sim
        sim.world = world
        sim.robot.set_world(world)
        old = sim.coverage
        sim.coverage = Coverage(world, self.params.body_radius, old.resolution)
        for x, y, _phi in sim._pose:  # noqa: SLF001 - the trail Simulation keeps
            sim.coverage.add(x, y)

    # -- what is drawn ---------------------------------------------------
    @property
    def firmware(self) -> Any:
        """The firmware's Robot object (SIL only: under PIL it runs in another process)."""
        return self.controller.robot

    def mode(self) -> int | None:
        if not self.pil:
            return int(self.firmware.mode)
        return None if self.last_telemetry is None else int(self.last_telemetry["mode"])  # type: ignore[call-overload]

    @property
    def pose(self) -> Pose:
        return self.sim.robot.pose

    @property
    def trail(self) -> list[Pose]:
        return self.sim._pose  # noqa: SLF001 - the poses at every control instant

    def counts(self) -> list[int]:
        """Reflected light per sensor, ADC counts (emitters on minus off) as the firmware last read them."""
        s = self.sim.robot.last_sense
        if s is None:
            return [0] * 8
        return [max(0, a - b) for a, b in zip(s.adc_on, s.adc_off)]

    def setpoints(self) -> tuple[int, int] | None:
        """The wheel-speed set-points the firmware decided last cycle (the fuzzy outputs in AUTONOMOUS), mm/s.

        Under PIL from TELEMETRY's sp_l, sp_r if the firmware sends them, else None."""
        if not self.pil:
            return int(self.firmware.setpoint_l), int(self.firmware.setpoint_r)
        f = self.last_telemetry
        if f is None or "sp_l" not in f:
            return None
        return int(f["sp_l"]), int(f["sp_r"])  # type: ignore[call-overload]

    def currents(self) -> tuple[int, int]:
        """The current references the firmware set last cycle, mA."""
        i_l, i_r = self.sim.robot.i_ref
        return int(round(1000 * i_l)), int(round(1000 * i_r))

    def after_frame(self) -> None:
        """Collision marks; TELEMETRY drained (to the recording when one is on)."""
        robot = self.sim.robot
        if robot.collisions > self._collisions_seen:
            self._collisions_seen = robot.collisions
            self.collision_marks.append(robot.pose[:2])
        if self.recorder is None:
            frames = self.controller.telemetry()  # nobody records: take them, or they pile up
            if frames:
                self.last_telemetry = frames[-1]

    def close(self) -> None:
        self.controller.close()

    def record(self, writer: RecordingWriter | None) -> None:
        if self.recorder is not None and writer is None:
            self.sim.record_to(None)
            self.recorder.close()
        elif writer is not None:
            self.controller.telemetry()  # start clean: only frames from now on
            self.sim.record_to(writer)
        self.recorder = writer


def compose(base: Pose, rel: Pose) -> Pose:
    """rel (a pose in base's frame) in the world frame."""
    c, s = math.cos(base[2]), math.sin(base[2])
    return (base[0] + c * rel[0] - s * rel[1], base[1] + s * rel[0] + c * rel[1], base[2] + rel[2])


def relative(base: Pose, pose: Pose) -> Pose:
    """pose in base's frame (the inverse of compose)."""
    c, s = math.cos(base[2]), math.sin(base[2])
    dx, dy = pose[0] - base[0], pose[1] - base[1]
    return (c * dx + s * dy, -s * dx + c * dy, pose[2] - base[2])


GHOST_HORIZON_S = 2.0  # the ghost runs on at most this long past the last frame: beyond, the signal is lost


class RealBot:
    """A robot on a serial port: pose from its TELEMETRY odometry, IR readings as they arrive, and its ghost.

    A Pico, or a virtual board's pty.  Its pose: odo_x, odo_y, odo_heading when the firmware sends
    them, else its encoders integrated here by the firmware's own odometry with the robot's geometry;
    placed at the room's start pose.
    """

    def __init__(self, link: SerialLink, start: Pose, params: RobotParams, floor_s: float = 0.0) -> None:
        self.link = link
        diameter_um, base_um, ticks = firmware_geometry(params)
        self.ghost = Ghost(base_um / 1e6, diameter_um / 1e6, ticks, floor_s=floor_s)
        self.start = start
        self.odometry = Odometry(int(round(2e6 * params.wheel_radius)), int(round(2e6 * params.half_axle)),
                                 int(round(params.ticks_per_rev)), EXACT)
        self.odo: Pose = (0.0, 0.0, 0.0)  # the robot's own odometry (its frame: where it started)
        self.anchor: Pose = (0.0, 0.0, 0.0)  # odometry pose that is shown at `start`
        self.source = "no TELEMETRY yet"
        self.trail: list[Pose] = []
        self.ir_counts = [0] * 8
        self.last: dict[str, object] | None = None
        self.frames = 0
        self.last_rx = -math.inf  # link clock, s
        self.orders: tuple[int, int] | None = None
        self._last_order = -math.inf
        self.recorder: RecordingWriter | None = None

    @classmethod
    def open(cls, port: str, start: Pose, params: RobotParams, floor_s: float = 0.0) -> RealBot:
        return cls(SerialLink.open(port), start, params, floor_s)

    @property
    def pose(self) -> Pose:
        """The raw pose: where the robot was when it sent its last frame."""
        return compose(self.start, relative(self.anchor, self.odo))

    def ghost_pose(self) -> Pose | None:
        """Where the ghost says the robot is now (placed like `pose`); None before the first frame."""
        now = min(self.link.now(), self.last_rx + GHOST_HORIZON_S)
        odo = self.ghost.predict(now)
        return None if odo is None else compose(self.start, relative(self.anchor, odo))

    def reset(self, start: Pose) -> None:
        """Show the robot at `start` from here on (its odometry goes on counting)."""
        self.start = start
        self.anchor = self.odo
        self.trail.clear()

    def poll(self) -> int:
        """Take the frames that have arrived (never waits); returns how many TELEMETRY."""
        n = 0
        for frame in self.link.poll(0.0):
            if frame.msg_type == M.TELEMETRY:
                self.telemetry(frame.fields)
                self.last_rx = frame.t
                self.ghost.on_telemetry(self._ghost_frame(frame.fields), frame.t)
                n += 1
        self._send_orders()
        return n

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
        self.trail.append(self.pose)
        if self.recorder is not None:
            self.recorder.telemetry(f)

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

    def _send_orders(self) -> None:
        """HOST-mode orders at 10 Hz while the user drives it (its watchdog stops it 200 ms after they end)."""
        now = self.link.now()
        if self.orders is not None and now - self._last_order >= 0.1:
            sent = self.link.send(M.COMMAND, {"mode": M.MODE_HOST, "left": self.orders[0], "right": self.orders[1]})
            self.ghost.on_command(sent.t, *self.orders)
            self.ghost.forget_before(sent.t - 5.0)
            self._last_order = now

    def release(self) -> None:
        """The user lets go: stop the robot now rather than at its watchdog."""
        self.orders = None
        sent = self.link.send(M.COMMAND, {"mode": M.MODE_STOP, "left": 0, "right": 0})
        self.ghost.on_command(sent.t, 0, 0)  # STOP: the wheels' set-points are zero from now on

    def set_param(self, name: str, value: int) -> None:
        self.link.send(M.PARAM_SET, {"param": M.param_by_name(name)[0], "value": int(value)})

    def counts(self) -> list[int]:
        return self.ir_counts

    def record(self, writer: RecordingWriter | None) -> None:
        if self.recorder is not None and writer is None:
            self.recorder.close()
        self.recorder = writer

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()
        self.link.close()
