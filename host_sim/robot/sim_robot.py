"""One simulated robot: the electrical I/O its firmware sees, over a BatchSim of one.

`sense()` gives what a HW_SENSE frame carries (tick, IR ADC counts with the emitters off and on,
encoder ticks, battery), `actuate()` takes what HW_ACTUATE carries, `advance(dt)` steps the physics
through `BatchSim.substep`, every robot's step whatever the batch size.
Equations: docs/dynamics.md ("One robot and the batch"), docs/contact.md, docs/motors.md.
"""
from __future__ import annotations

import numpy as np

from host_sim.physics import dynamics, motors
from host_sim.robot.batch import BatchSim
from host_sim.sensors import ir_sensor
from host_sim.controller.hardware_io import TICK_MASK, Actuate, Sense, firmware_command
from host_sim.physics.params import RobotParams
from host_sim.physics.world import World



class SimRobot:
    _ir_history: ir_sensor.PoseHistory | None = None  # the poses at the last readings, for ir_latency

    def __init__(self, world: World, params: RobotParams, pose: tuple[float, float, float] | None = None,
                 seed: int | None = 0, noise: bool = True, bench: bool = False) -> None:
        """bench: the body held, the wheels off the floor (a bench recording's replay, BatchSim's bench)."""
        self.p = params
        self._command = firmware_command(params)  # once, not each control cycle: the drive does not change
        x, y, phi = pose if pose is not None else world.start
        q = dynamics.q_from_axle_pose(float(x), float(y), float(phi), params)
        self.batch = BatchSim(world, params, q=[q], substeps=1, bench=bench)  # holds the state and steps it
        self.i_ref = (0.0, 0.0)  # the commands in the drive's unit (A for a current drive)
        self.emitter_pct = 0  # set by the last actuation
        self.emitter_used = 0  # in force for the last sense(): its on-readings' light power
        self.rng = np.random.default_rng(seed) if noise else None
        self.last_sense: Sense | None = None

    # ------------------------------------------------------------------ the state, held by the batch
    @property
    def world(self) -> World:
        return self.batch.world

    @property
    def q(self) -> tuple[float, ...]:
        """(x_G, y_G, phi, theta_l, theta_r) as in host_sim/physics/dynamics.py."""
        return self.batch.floats_of_one()[0]

    @q.setter
    def q(self, q: tuple[float, ...]) -> None:
        self.batch.q[0] = q

    @property
    def v(self) -> tuple[float, float]:
        """(wheel speed left, right), rad/s."""
        return self.batch.floats_of_one()[1]  # type: ignore[return-value]

    @v.setter
    def v(self, v: tuple[float, float]) -> None:
        self.batch.v[0] = v

    @property
    def slip(self) -> tuple[float, float, float] | None:
        """(u, l, omega) of C while a wheel slips, else None (rolling)."""
        return tuple(self.batch.body[0].tolist()) if self.batch.slipping[0] else None  # type: ignore[return-value]

    @slip.setter
    def slip(self, body: tuple[float, float, float] | None) -> None:
        self.batch.slipping[0] = body is not None
        if body is not None:
            self.batch.body[0] = body

    @property
    def t(self) -> float:
        """Simulated seconds."""
        return self.batch.t  # type: ignore[return-value]

    @t.setter
    def t(self, t: float) -> None:
        self.batch.t = t

    @property
    def current(self) -> tuple[float, float]:
        """A actually flowing in the last substep (left, right)."""
        return tuple(self.batch.current[0].tolist())  # type: ignore[return-value]

    @property
    def vbat(self) -> float:
        """V at the battery's terminals: it sags with battery_resistance under the current drawn."""
        return float(self.batch.vbat[0])

    @property
    def collisions(self) -> int:
        return int(self.batch.collisions[0])

    @property
    def in_contact(self) -> bool:
        return bool(self.batch.in_contact[0])

    @property
    def pose(self) -> tuple[float, float, float]:
        """(x, y, phi) of C, the centre of the wheel axle."""
        q = self.q
        x, y = dynamics.axle_centre(q, self.p)
        return x, y, q[2]

    # ------------------------------------------------------------------ what the firmware sees
    def encoder_ticks(self) -> tuple[int, int]:
        if self.batch.gear_gap is None:
            q = self.q
            th_l, th_r = q[3], q[4]
        else:  # the encoders are on the motors, a gear's play from the wheels
            th_l, th_r = self.batch.encoder_angles()[0].tolist()
        return motors.encoder_ticks(th_l, self.p, 0), motors.encoder_ticks(th_r, self.p, 1)

    def sense(self) -> Sense:
        self.emitter_used = self.emitter_pct
        x, y, phi = self.pose
        t_read = self.t
        if self.p.ir_latency > 0:  # the readings describe the pose of ir_latency ago
            x, y, phi, t_read = self._past_pose(x, y, phi)
        off, on = ir_sensor.read_sensors(self.world, (x, y, phi), float(self.emitter_pct), t_read, self.p, self.rng)
        enc_l, enc_r = self.encoder_ticks()
        s = Sense(int(round(self.t * 1000)) & TICK_MASK, off.tolist(), on.tolist(), enc_l, enc_r,
                  int(round(self.vbat * 1000)))
        self.last_sense = s
        return s

    def _past_pose(self, x: float, y: float, phi: float) -> tuple[float, float, float, float]:
        """(x, y, phi, t) ir_latency ago: linear between the poses of the earlier readings (ir_sensor.PoseHistory)."""
        if self._ir_history is None:
            self._ir_history = ir_sensor.PoseHistory(self.p.ir_latency)
        self._ir_history.add(self.t, (x, y, phi))
        t = self.t - self.p.ir_latency
        px, py, pphi = self._ir_history.at(t).tolist()
        return px, py, pphi, t

    def actuate(self, a: Actuate) -> None:
        """The firmware's outputs: its current references reach the drive as its HAL writes them
        (hardware_io.firmware_command), a wheel_speed robot's board as set-points (the duty times its top speed)."""
        self.i_ref = (self._command(a.i_left_ma), self._command(a.i_right_ma))
        self.emitter_pct = a.emitter_pct

    def advance(self, dt: float) -> None:
        """One substep of dt seconds under the last actuation's current references (BatchSim.substep)."""
        self.batch.substep(self.i_ref, dt)

    def set_world(self, world: World) -> None:
        """Put the robot, where it stands, in an edited world (walls drawn or moved around it)."""
        self.batch.set_world(world)
