"""One simulated robot: its physics and the electrical I/O its firmware sees.

The state is the paper's q = (x_c, y_c, phi, theta_l, theta_r), (x_c, y_c)
being the centre of mass G (host_sim/dynamics.py), with the wheel speeds
v = (theta_l_dot, theta_r_dot).  The robot's pose (x, y, phi) everywhere
else - sensors, body disc, collisions, the tracker columns of recordings - is
that of C, the centre of the wheel axle.  Each substep: the current
references go through the motor model (current regulator, back-EMF,
current limit, friction) to wheel torques, the reduced Lagrangian dynamics
advance q and v, and contact with a wall is resolved (the robot is pushed
back out and its wheels stall; the start of each contact is a collision).

`sense()` gives what a HW_SENSE frame carries (tick, IR ADC counts with
the emitters off and on at the power of the last actuation, encoder ticks,
battery), `actuate()` takes what HW_ACTUATE carries.
"""
from __future__ import annotations

import math

import numpy as np

from host_sim import dynamics, ir_sensor, motors
from host_sim.interface import TICK_MASK, Actuate, Sense
from host_sim.params import RobotParams
from host_sim.world import World



class SimRobot:
    def __init__(self, world: World, params: RobotParams, pose: tuple[float, float, float] | None = None,
                 seed: int | None = 0, noise: bool = True) -> None:
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
        self._clearance = -1.0  # distance the body can still travel before it may touch a wall
        self._checked_at = (0.0, 0.0)
        self.last_sense: Sense | None = None

    @property
    def pose(self) -> tuple[float, float, float]:
        """(x, y, phi) of C, the centre of the wheel axle."""
        x, y = dynamics.axle_centre(self.q, self.p)
        return x, y, self.q[2]

    def encoder_ticks(self) -> tuple[int, int]:
        return motors.encoder_ticks(self.q[3], self.p), motors.encoder_ticks(self.q[4], self.p)

    def sense(self) -> Sense:
        self.emitter_used = self.emitter_pct
        x, y, phi = self.pose
        off, on = ir_sensor.read_sensors_lists(self.world, x, y, phi, float(self.emitter_pct), self.t, self.p,
                                               self.rng)
        enc_l, enc_r = self.encoder_ticks()
        s = Sense(int(round(self.t * 1000)) & TICK_MASK, off, on, enc_l, enc_r,
                  int(round(self.p.battery_voltage * 1000)))
        self.last_sense = s
        return s

    def actuate(self, a: Actuate) -> None:
        self.i_ref = (a.i_left_ma / 1000.0, a.i_right_ma / 1000.0)
        self.emitter_pct = a.emitter_pct

    def advance(self, dt: float) -> None:
        """One substep of dt seconds."""
        p = self.p
        tau_l, i_l = motors.wheel_torque(self.i_ref[0], self.v[0], p)
        tau_r, i_r = motors.wheel_torque(self.i_ref[1], self.v[1], p)
        self.current = (i_l, i_r)
        self.q, self.v = dynamics.step(self.q, self.v, (tau_l, tau_r), dt, p)
        self.t += dt
        self._resolve_contact()

    def set_world(self, world: World) -> None:
        """Put the robot, where it stands, in an edited world (walls drawn or moved around it)."""
        self.world = world
        self._clearance = -1.0  # the broad phase's clearance was measured against the old walls

    def _resolve_contact(self) -> None:
        cx, cy = dynamics.axle_centre(self.q, self.p)
        # Broad phase: no wall can be reached before the body has moved by
        # the clearance found at the last check.
        moved = math.hypot(cx - self._checked_at[0], cy - self._checked_at[1])
        if moved < self._clearance:
            return
        dist, normal = self.world.nearest_wall(np.array([[cx, cy]]))
        d = float(dist[0])
        r = self.p.body_radius
        self._checked_at = (cx, cy)
        self._clearance = d - r - 0.002 if d > r + 0.004 else -1.0
        if d < r:
            # Push the body back out along the wall normal; the wheels stall
            # against the wall (no bouncing, no sliding).
            nx, ny = float(normal[0, 0]), float(normal[0, 1])
            q = list(self.q)
            q[0] += (r - d) * nx
            q[1] += (r - d) * ny
            self.q = tuple(q)
            self._clearance = -1.0
            heading_into = math.cos(q[2]) * nx + math.sin(q[2]) * ny
            forward = self.v[0] + self.v[1]
            if forward * heading_into < 0:  # driving into the wall: the translation stops
                spin = (self.v[1] - self.v[0]) / 2
                self.v = (-spin, spin)
            if not self.in_contact:
                self.collisions += 1
            self.in_contact = True
        elif d > r + 0.002:  # a little hysteresis: grazing is one contact, not many
            self.in_contact = False
