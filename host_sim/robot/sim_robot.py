"""One simulated robot: its physics and the electrical I/O its firmware sees.

`sense()` gives what a HW_SENSE frame carries (tick, IR ADC counts with the emitters off and on,
encoder ticks, battery), `actuate()` takes what HW_ACTUATE carries, `advance(dt)` steps the physics:
rolling (drivetrain) while the wheels hold and no wall is hit, else the contact step.  With a drive
effect of the library the robot runs as a BatchSim of one (the effects' physics is written once).
Equations: docs/dynamics.md, docs/contact.md, docs/motors.md.
"""
from __future__ import annotations

import math

import numpy as np

from host_sim.physics import contact, drivetrain, drivetrain_effects, dynamics, motors
from host_sim.robot.batch import BatchSim
from host_sim.sensors import ir_sensor
from host_sim.controller.hardware_io import TICK_MASK, Actuate, Sense
from host_sim.physics.params import RobotParams
from host_sim.physics.world import World



class SimRobot:
    _ir_history: ir_sensor.PoseHistory | None = None  # the poses at the last readings, for ir_latency

    def __init__(self, world: World, params: RobotParams, pose: tuple[float, float, float] | None = None,
                 seed: int | None = 0, noise: bool = True, bench: bool = False) -> None:
        """bench: the body held, the wheels off the floor (a bench recording's replay, BatchSim's bench)."""
        self.world = world
        self.p = params
        x, y, phi = pose if pose is not None else world.start
        self.q: tuple[float, ...] = dynamics.q_from_axle_pose(float(x), float(y), float(phi), params)
        self.v: tuple[float, float] = (0.0, 0.0)
        self.t = 0.0  # simulated seconds
        self.i_ref = (0.0, 0.0)  # A
        self.current = (0.0, 0.0)  # A actually flowing
        self.emitter_pct = 0  # set by the last actuation
        self.emitter_used = 0  # in force for the last sense(): its on-readings' light power
        self.rng = np.random.default_rng(seed) if noise else None
        self.collisions = 0
        self.in_contact = False
        self.slip: tuple[float, float, float] | None = None  # (u, l, omega) while a wheel slips
        self._forces: tuple[list[list[float]], dict[int, list[float]]] | None = None  # last contact forces
        self._gap_at_check = -1.0  # the smallest wall gap at the last wall test (broad phase)
        self._checked_at = (0.0, 0.0, 0.0)  # G and phi at the last wall test
        self.last_sense: Sense | None = None
        # V at the battery's terminals: at rest only the electronics draw (it sags with battery_resistance)
        self.vbat = float(params.battery_voltage - params.battery_resistance * params.electronics_current)
        # With any drive effect of the library present the robot runs as a BatchSim of one: the effects'
        # physics is written once (host_sim/physics/drivetrain_effects.py), so this and the batch twin are the same code.
        self._effects = None
        if drivetrain_effects.active(params) or params.actuator_delay != 0.0 or bench:
            self._effects = BatchSim(world, params, q=[self.q], v=[self.v], substeps=1, bench=bench)

    @property
    def pose(self) -> tuple[float, float, float]:
        """(x, y, phi) of C, the centre of the wheel axle."""
        x, y = dynamics.axle_centre(self.q, self.p)
        return x, y, self.q[2]

    def encoder_ticks(self) -> tuple[int, int]:
        th_l, th_r = self.q[3], self.q[4]
        if self._effects is not None and self._effects.gear_gap is not None:  # the encoders are on the motors
            th_l, th_r = th_l + float(self._effects.gear_gap[0, 0]), th_r + float(self._effects.gear_gap[0, 1])
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
        self.i_ref = (a.i_left_ma / 1000.0, a.i_right_ma / 1000.0)
        self.emitter_pct = a.emitter_pct

    def advance(self, dt: float) -> None:
        """One substep of dt seconds: rolling (drivetrain.drive_step) while the wheels hold and no wall is hit,
        else the contact step (contact.slip_step, docs/dynamics.md "Contact")."""
        if self._effects is not None:
            self._advance_effects(dt)
            return
        p = self.p
        q0, v0 = self.q, self.v
        rolled = False
        if self.slip is None:
            q1, v1, tau, self.current = drivetrain.drive_step(q0, v0, self.i_ref, dt, p)
            rolled = contact.traction_ok(v0, v1, tau, dt, p)
        walls = self._walls_in_reach(q0, q1 if rolled else None, dt)
        if rolled and walls:
            # the rolling step is kept unless it takes the rim into a wall (linearised gap: the
            # distance to a segment is convex in C, so this never misses a contact)
            d = p.com_offset
            dx = q1[0] - q0[0] - d * (math.cos(q1[2]) - math.cos(q0[2]))
            dy = q1[1] - q0[1] - d * (math.sin(q1[2]) - math.sin(q0[2]))
            rolled = all(gap + nx * dx + ny * dy >= 0.0 for gap, nx, ny, _i in walls)
        if rolled:
            self.q, self.v = q1, v1
            self._forces = None
        else:
            tl, il, sl = motors.wheel_torque_slope(self.i_ref[0], v0[0], p)
            tr, ir, sr = motors.wheel_torque_slope(self.i_ref[1], v0[1], p)
            self.current = (il, ir)
            warm = None
            if self._forces is not None:  # start from the last step's contact forces
                wheel_f, wall_f = self._forces
                warm = (wheel_f, [wall_f.get(w[3], [0.0, 0.0]) for w in walls])
            self.q, self.v, self.slip, pushed, (wheel_f, wall_list) = contact.slip_step(
                q0, v0, self.slip, (tl, tr), (sl, sr), dt, p, walls, warm)
            self._forces = (wheel_f, {w[3]: f for w, f in zip(walls, wall_list)})
            if pushed and not self.in_contact:
                self.collisions += 1
            self.in_contact = self.in_contact or pushed
        self.t += dt

    def set_world(self, world: World) -> None:
        """Put the robot, where it stands, in an edited world (walls drawn or moved around it)."""
        self.world = world
        self._gap_at_check = -1.0  # the broad phase's gap was measured against the old walls
        self._forces = None  # contact forces are kept by wall index, which the edit may have changed
        if self._effects is not None:
            self._effects.set_world(world)

    def _advance_effects(self, dt: float) -> None:
        """advance() through the BatchSim of one that carries the effects (state copied in and out, so a
        caller may set q and v as with the nominal robot)."""
        twin = self._effects
        assert twin is not None
        twin.q[0], twin.v[0], twin.t = self.q, self.v, self.t
        twin.slipping[0] = self.slip is not None
        if self.slip is not None:  # set from outside too (a replay started sliding)
            twin.body[0] = self.slip
        twin.substep(self.i_ref, dt)
        self.q = tuple(float(x) for x in twin.q[0])
        self.v = (float(twin.v[0, 0]), float(twin.v[0, 1]))
        self.current = (float(twin.current[0, 0]), float(twin.current[0, 1]))
        self.vbat = float(twin.vbat[0])
        self.collisions, self.in_contact = int(twin.collisions[0]), bool(twin.in_contact[0])
        self.slip = tuple(float(x) for x in twin.body[0]) if twin.slipping[0] else None  # type: ignore[assignment]
        self.t += dt

    def _walls_in_reach(self, q0: tuple[float, ...], q1: tuple[float, ...] | None,
                        dt: float) -> list[tuple[float, float, float, int]]:
        """The walls the step from q0 (to q1 when rolling) may touch, (gap, nx, ny) each.

        Broad phase: no test while the smallest gap at the last test exceeds how far C may have
        moved since (C = G - d e moves at most |dG| + d |dphi|) plus how far this step takes it."""
        d = self.p.com_offset
        chk = self._checked_at
        moved = math.hypot(q0[0] - chk[0], q0[1] - chk[1]) + d * abs(q0[2] - chk[2])
        if q1 is not None:
            travel = math.hypot(q1[0] - q0[0], q1[1] - q0[1]) + d * abs(q1[2] - q0[2])
        else:
            u, l, _om = self.slip if self.slip is not None else contact.body_velocity(self.v, self.p)
            travel = dt * (abs(u) + abs(l))
        within = travel + contact.REACH_MARGIN
        if moved + within < self._gap_at_check:
            if self._gap_at_check - moved > contact.CONTACT_HYSTERESIS:
                self.in_contact = False
            return []
        cx, cy = q0[0] - d * math.cos(q0[2]), q0[1] - d * math.sin(q0[2])
        walls, gmin = contact.walls_in_reach(self.world, cx, cy, self.p.body_radius, within)
        self._checked_at = (q0[0], q0[1], q0[2])
        self._gap_at_check = gmin
        if gmin > contact.CONTACT_HYSTERESIS:  # a little hysteresis: grazing is one contact, not many
            self.in_contact = False
        return walls
