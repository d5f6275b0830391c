"""The two simulated robots of the paper's application (§4, Fig. 14), as the window sees them.

`SimBot`: the simulated robot (AUTONOMOUS, the fuzzy explorer) and the user robot (HOST, the user's
orders), each running the firmware itself; the real robot is tools/gui/real_robot.py.  See docs/gui.md.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from host_sim.sensors.ir_sensor import BEARINGS
from host_sim.loops.live import LiveStepper
from host_sim.physics.params import RobotParams
from host_sim.board.pil import PilController
from host_sim.recordings.recording import RecordingWriter
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

    def place(self, pose: Pose) -> None:
        """Put the robot at pose (dragged or turned by the user); its wheels' angles, so its encoders, go on."""
        from host_sim.physics.dynamics import q_from_axle_pose

        robot = self.sim.robot
        robot.q = q_from_axle_pose(*pose, self.params, robot.q[3], robot.q[4])
        robot.set_world(robot.world)  # the broad phase's gap was measured from where it was

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
