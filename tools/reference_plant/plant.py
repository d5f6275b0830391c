"""The plant: the MuJoCo robot stepped with its drivers, battery, encoders, IR ring and tracker.

Each 1 ms MuJoCo step its own drivers (current loops, or an H-bridge: hbridge.py) turn the commands into wheel
torques; `sense()` and `actuate()` speak host_sim's Sense / Actuate, so any of the twin's controllers drives it
as it drives the twin's SimRobot.  Equations and readings: docs/proving-ground.md, "The robot in MuJoCo".
"""
from __future__ import annotations

import math
from collections import deque

import mujoco  # type: ignore[import-untyped]
import numpy as np

from host_sim.controller.hardware_io import TICK_MASK, Actuate, Sense
from host_sim.physics.world import World
from tools.reference_plant import hbridge, ir_law, ir_paper
from tools.reference_plant.robot_model import SLIP_MIN_SPEED, PlantSpec, build_model, drive_joint, ir_group_mask
from tools.reference_plant.wheel_speed_loop import WheelSpeedLoop

N_SENSORS = 8
RAY_HEIGHT = 0.03  # m above the floor: the IR surfaces' mid-height
SETTLE_S = 0.3  # s the robot rests on the floor before t = 0
LOOP_STEPS = 5  # the drivers' current loop runs at 5 kHz: 5 steps per MuJoCo step
ROLLING_SMOOTH = 0.2  # per step: the tread speed the slip damper is set from follows over ~5 ms
CASTER_SLIDE = 0.005  # m/s over which the caster's rolling drag builds up (no chatter at rest)
CABLE_HEIGHT = 0.03  # m above the floor where the tether pulls on the body's rear


def edges_passed(x: float, edges: tuple[float, ...]) -> int:
    """Edges passed at position x (ticks): edge j sits at j + edges[j mod len(edges)] (all at j if none)."""
    j = math.floor(x)
    if not edges:
        return j
    n = len(edges)
    if x < j + edges[j % n]:
        return j - 1
    if x >= j + 1 + edges[(j + 1) % n]:
        return j + 1
    return j


class Plant:
    """One MuJoCo robot in a world; the same sense/actuate interface as host_sim's SimRobot."""

    def __init__(self, spec: PlantSpec, world: World | None, pose: tuple[float, float, float] | None = None,
                 seed: int = 0, timestep: float = 0.001) -> None:
        if min(spec.inductance) <= 0 and (spec.drive != "current" or spec.current_loop_hz > 0):
            raise ValueError(f"a current loop or an H-bridge drives the motor's winding: its inductance must be "
                             f"> 0, got {spec.inductance}")
        self.spec = spec
        self.world = world
        self.model = build_model(spec, world, timestep)
        self.data = mujoco.MjData(self.model)
        self.dt = timestep
        self.rng = np.random.default_rng([seed, 0])  # IR and battery measurement noise
        self.tracker_rng = np.random.default_rng([seed, 1])
        m = self.model
        self._drive_q = [m.joint(drive_joint(spec, k)).qposadr[0] for k in range(2)]
        self._drive_v = [m.joint(drive_joint(spec, k)).dofadr[0] for k in range(2)]
        self._wheel_q = [m.joint(f"wheel_{s}").qposadr[0] for s in "lr"]
        self._wheel_v = [m.joint(f"wheel_{s}").dofadr[0] for s in "lr"]
        self._tread_v = [m.joint(f"tread_{s}").dofadr[0] for s in "lr"] if spec.slip_stiffness > 0 else []
        self._caster = m.geom("caster").id
        self._loop = [0.0, 0.0]  # the current loops' integrators (V)
        self._coil = [0.0, 0.0]  # the current in each winding now (A)
        self._rolling = [0.0, 0.0]  # each tread's rolling speed (rad/s), smoothed over a few steps
        self._velocity = np.zeros(6)
        self._chassis = m.body("chassis").id
        # the IR ring's law: the plant's own curve, or the paper's for the datasheet robot (ir_paper.py)
        self._optics = ir_paper if spec.ir.get("law") == "paper" else ir_law
        self._ray_mask = ir_group_mask()
        self._geomid = np.zeros(1, dtype=np.int32)
        self._normal = np.zeros(3)
        self.cmd = (0.0, 0.0)  # the command in force, in the drive's unit (A: what the current driver regulates to)
        self._speed_loop = WheelSpeedLoop(spec.speed_kp, spec.speed_ki, spec.speed_loop_period,
                                          spec.board_ticks_per_rev) if spec.drive == "wheel_speed" else None
        self._loop_volts = (0.0, 0.0)  # the speed loop's output now (V)
        self.current = (0.0, 0.0)  # A flowing
        self._pending: deque[tuple[float, tuple[float, float]]] = deque()
        self.emitter_pct = 0
        self.v_term = spec.battery_voltage
        self._phi = 0.0
        self._history: deque[tuple[float, float, float, float]] = deque()  # (t, x, y, phi) for IR latency
        self._place(pose if pose is not None else (world.start if world is not None else (0.0, 0.0, 0.0)))

    # ------------------------------------------------------------------ set-up
    def _place(self, pose: tuple[float, float, float]) -> None:
        """Put C at pose, let the robot settle on its wheels and caster, then zero the encoders and the clock."""
        x, y, phi = (float(v) for v in pose)
        d = self.data
        d.qpos[0:2] = (x, y)
        d.qpos[3:7] = (math.cos(phi / 2), 0.0, 0.0, math.sin(phi / 2))
        mujoco.mj_forward(self.model, d)
        for _ in range(int(round(SETTLE_S / self.dt))):
            mujoco.mj_step(self.model, d)
        for k in range(2):  # the encoders count from 0, mid-tick (no count from a micro-motion at rest)
            zero = float(d.qpos[self._drive_q[k]]) - math.pi / self.spec.ticks_per_rev[k]
            d.qpos[self._wheel_q[k]] -= zero
            if self._drive_q[k] != self._wheel_q[k]:
                d.qpos[self._drive_q[k]] -= zero
        d.time = 0.0
        mujoco.mj_forward(self.model, d)
        self._phi = phi
        self._phi = self.true_pose()[2]
        self._history.append((0.0, *self.true_pose()))

    # ------------------------------------------------------------------ state
    @property
    def t(self) -> float:
        return float(self.data.time)

    def true_pose(self) -> tuple[float, float, float]:
        """(x, y, phi) of C, phi continuous (not wrapped)."""
        d = self.data
        x, y = float(d.xpos[self._chassis, 0]), float(d.xpos[self._chassis, 1])
        mat = d.xmat[self._chassis]
        yaw = math.atan2(float(mat[3]), float(mat[0]))
        self._phi += (yaw - self._phi + math.pi) % (2 * math.pi) - math.pi
        return x, y, self._phi

    def tracker_pose(self) -> tuple[float, float, float]:
        """What an overhead camera reports: the pose of C with Gaussian noise."""
        x, y, phi = self.true_pose()
        s = self.spec
        n = self.tracker_rng.standard_normal(3)
        return x + s.tracker_noise_xy * n[0], y + s.tracker_noise_xy * n[1], phi + s.tracker_noise_phi * n[2]

    def wheel_speeds(self) -> tuple[float, float]:
        """Drive joint speeds (rad/s)."""
        return float(self.data.qvel[self._drive_v[0]]), float(self.data.qvel[self._drive_v[1]])

    def encoder_position(self) -> tuple[float, float]:
        """Each encoder's position in ticks, not rounded: what a perfect twin would predict of its counts."""
        d, s = self.data, self.spec
        return tuple(float(d.qpos[self._drive_q[k]]) * s.ticks_per_rev[k] / (2 * math.pi)
                     for k in range(2))  # type: ignore[return-value]

    def encoder_ticks(self) -> tuple[int, int]:
        """The counts: edges passed (each edge where the plant's own encoder has it), plus any drift."""
        s = self.spec
        return tuple(edges_passed(x, s.encoder_edges[k]) + math.floor(s.encoder_drift[k] * self.t)
                     for k, x in enumerate(self.encoder_position()))  # type: ignore[return-value]

    # ------------------------------------------------------------------ I/O
    def actuate(self, a: Actuate) -> None:
        """The firmware's current references (mA), for a current drive."""
        self.command((a.i_left_ma / 1000.0, a.i_right_ma / 1000.0), a.emitter_pct)

    def command(self, cmd: tuple[float, float], emitter_pct: int) -> None:
        """Commands in the drive's unit (A, V, a signed duty, or a wheel-speed set-point in rad/s)."""
        self._pending.append((self.t + self.spec.actuator_delay - 1e-9, (float(cmd[0]), float(cmd[1]))))
        self.emitter_pct = emitter_pct

    def sense(self) -> Sense:
        off, on = self.read_ir()
        enc_l, enc_r = self.encoder_ticks()
        vbat = self.v_term + self.spec.vbat_noise * float(self.rng.standard_normal())
        if self.spec.vbat_lsb > 0:  # the battery ADC's counts
            vbat = round(vbat / self.spec.vbat_lsb) * self.spec.vbat_lsb
        return Sense(int(round(self.t * 1000)) & TICK_MASK, off, on, enc_l, enc_r, int(round(vbat * 1000)))

    # ------------------------------------------------------------------ physics
    def advance(self, duration: float) -> None:
        """Step the physics for `duration` seconds (a whole number of MuJoCo steps)."""
        m, d = self.model, self.data
        for _ in range(int(round(duration / self.dt))):
            while self._pending and self._pending[0][0] <= d.time:
                self.cmd = self._pending.popleft()[1]
            if self._speed_loop is not None:
                self._loop_volts = self._speed_loop.volts(self.t, self.encoder_ticks(), self.cmd, self.v_term)
            self._drive()
            self._loads()
            mujoco.mj_step(m, d)
            if self.spec.ir_latency > 0:
                mujoco.mj_kinematics(m, d)
                self._remember_pose()
        # mj_step leaves the bodies' frames where the step began; the encoders read the joints where it ended.
        # One instant for the pose, the tracker, the IR ring's rays and the encoders: the frames of now.
        mujoco.mj_kinematics(m, d)

    def torque_constant(self, k: int) -> float:
        """Wheel k's torque constant now (a weakening motor loses weak_fraction of it over 1 s from weak_time)."""
        s = self.spec
        if k != s.weak_wheel or self.t <= s.weak_time:
            return s.torque_constant[k]
        u = min(1.0, self.t - s.weak_time)
        return s.torque_constant[k] * (1.0 - s.weak_fraction * u * u * (3.0 - 2.0 * u))

    def _drive(self) -> None:
        """The drivers and the battery: currents for this step, motor torques (with the gear's ripple) into
        data.ctrl."""
        s, d = self.spec, self.data
        v_bat = self.v_term
        power = 0.0
        currents = []
        for k in range(2):
            w = float(d.qvel[self._drive_v[k]])
            kt = self.torque_constant(k)
            emf = kt * s.gear_ratio * w
            i, p = self._regulated(k, emf, v_bat) if s.drive == "current" else self._bridged(k, emf, v_bat)
            torque = s.gear_efficiency * s.gear_ratio * kt * i
            if s.ripple[k] > 0:
                angle = float(d.qpos[self._drive_q[k]]) * s.ripple_teeth[k] + s.ripple_phase[k]
                torque *= 1.0 + s.ripple[k] * math.sin(angle)
            d.ctrl[k] = torque
            power += p
            currents.append(i)
        self.current = (currents[0], currents[1])
        # the drivers take their power at the terminals (tests/test_plant_drives.py::
        # test_the_battery_gives_its_drivers_current_at_its_terminals)
        i_batt = s.quiescent_current + power / v_bat
        self.v_term = s.battery_voltage - s.battery_resistance * i_batt

    def _regulated(self, k: int, emf: float, v_bat: float) -> tuple[float, float]:
        """The current driver: (the step's mean current, the power it draws), the reference within the limit."""
        s = self.spec
        i_ref = min(max(self.cmd[k], -s.current_limit), s.current_limit)
        if s.current_loop_hz > 0:
            i, u = self._current_loop(k, i_ref, emf, v_bat)
        else:  # the ideal driver: the reference, within what the voltage allows
            ohm = s.armature_resistance[k]
            i = min(max(i_ref, (-v_bat - emf) / ohm), (v_bat - emf) / ohm)
            u = ohm * i + emf
        return i, u * i

    def _bridged(self, k: int, emf: float, v_bat: float) -> tuple[float, float]:
        """The H-bridge at the drive's duty, PWM cycle by cycle over the step: (mean current, battery power)."""
        s = self.spec
        command = self._loop_volts[k] if s.drive == "wheel_speed" else self.cmd[k]
        duty = command if s.drive == "duty" else command / max(v_bat, 1e-6)
        self._coil[k], i, i_batt = hbridge.step(
            self._coil[k], hbridge.after_deadband(duty, s.driver_deadband), emf, v_bat, s.armature_resistance[k],
            s.inductance[k], s.pwm_frequency, s.pwm_decay == "brake", self.dt)
        return i, v_bat * i_batt

    def _current_loop(self, k: int, i_ref: float, emf: float, v_bat: float) -> tuple[float, float]:
        """One step of a digital PI current loop (LOOP_STEPS per step) on the motor's R and L, its output
        saturating at the battery voltage; returns the step's mean current and terminal voltage."""
        s = self.spec
        ohm, henry = s.armature_resistance[k], s.inductance[k]
        h = self.dt / LOOP_STEPS
        wc = 2 * math.pi * s.current_loop_hz
        kp, ki = wc * henry, wc * ohm  # the PI's zero cancels the motor's pole: a first-order loop at wc
        decay = math.exp(-ohm * h / henry)
        i, integ = self._coil[k], self._loop[k]
        i_sum = u_sum = 0.0
        for _ in range(LOOP_STEPS):
            err = i_ref - i
            integ = min(max(integ + ki * err * h, -v_bat), v_bat)  # clamped: no wind-up at saturation
            u = min(max(kp * err + integ, -v_bat), v_bat)
            i_inf = (u - emf) / ohm  # the RL circuit held at u for h, exactly
            i = i_inf + (i - i_inf) * decay
            i_sum += i
            u_sum += u
        self._loop[k], self._coil[k] = integ, i
        return i_sum / LOOP_STEPS, u_sum / LOOP_STEPS

    def _loads(self) -> None:
        """The loads MuJoCo's joints and contacts do not give: the Stribeck fall of the axles' friction in
        motion, the tyres' slip damping, the caster's rolling drag and the tether (into qfrc_applied)."""
        s, m, d = self.spec, self.model, self.data
        d.qfrc_applied[:] = 0.0
        for k in range(2):
            v = self._drive_v[k]
            w = float(d.qvel[v])
            # frictionloss holds the breakaway torque; in motion it falls to Coulomb over stribeck_speed.
            drop = s.coulomb_friction[k] * (s.stiction_ratio[k] - 1.0)
            if drop > 0:
                d.qfrc_applied[v] += drop * (1.0 - math.exp(-(w / s.stribeck_speed) ** 2)) * math.copysign(1.0, w)
            if self._tread_v:
                # slip = F / C of the ground's speed (the tread's, which rolls): the tread turns against the
                # hub at F r / c, so c = r C / |w_tread| (MuJoCo integrates the damping implicitly)
                rolling = float(d.qvel[self._wheel_v[k]] + d.qvel[self._tread_v[k]])  # the hub's, not a rotor's
                self._rolling[k] += ROLLING_SMOOTH * (rolling - self._rolling[k])  # no step-to-step chatter
                m.dof_damping[self._tread_v[k]] = s.wheel_radius[k] * s.slip_stiffness / max(abs(self._rolling[k]),
                                                                                             SLIP_MIN_SPEED)
        if s.caster_rolling > 0:
            self._caster_drag()
        if s.cable_drag > 0:
            self._cable()

    def _caster_drag(self) -> None:
        """The ball caster's rolling drag: caster_rolling times its normal load, against its motion."""
        m, d = self.model, self.data
        load = 0.0
        force = np.zeros(6)
        for c in range(d.ncon):
            if self._caster in (d.contact[c].geom1, d.contact[c].geom2):
                mujoco.mj_contactForce(m, d, c, force)
                load += abs(float(force[0]))
        if load <= 0:
            return
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_GEOM, self._caster, self._velocity, 0)
        vx, vy = float(self._velocity[3]), float(self._velocity[4])
        speed = math.hypot(vx, vy)
        if speed <= 0:
            return
        f = self.spec.caster_rolling * load * math.tanh(speed / CASTER_SLIDE) / speed
        mujoco.mj_applyFT(m, d, np.array([-f * vx, -f * vy, 0.0]), np.zeros(3), d.geom_xpos[self._caster].copy(),
                          self._chassis, d.qfrc_applied)

    def _cable(self) -> None:
        """A tether from cable_anchor to the body's rear, pulling back with cable_drag times the distance."""
        s, d = self.spec, self.data
        x, y = float(d.xpos[self._chassis, 0]), float(d.xpos[self._chassis, 1])
        dx, dy = s.cable_anchor[0] - x, s.cable_anchor[1] - y
        dist = math.hypot(dx, dy)
        if dist <= 1e-6:
            return
        mat = d.xmat[self._chassis]
        rear = np.array([x - s.body_radius * float(mat[0]), y - s.body_radius * float(mat[3]), CABLE_HEIGHT])
        mujoco.mj_applyFT(self.model, d, np.array([s.cable_drag * dx, s.cable_drag * dy, 0.0]), np.zeros(3), rear, self._chassis,
                          d.qfrc_applied)

    def _remember_pose(self) -> None:
        h = self._history
        h.append((self.t, *self.true_pose()))
        while len(h) > 2 and h[1][0] <= self.t - self.spec.ir_latency:
            h.popleft()

    # ------------------------------------------------------------------ IR ring
    def _ir_pose(self) -> tuple[float, float, float]:
        if self.spec.ir_latency <= 0:
            return self.true_pose()
        return self._history[0][1:]

    def _ray(self, origin: np.ndarray, direction: np.ndarray) -> tuple[float, float]:
        """(distance, |cos| between ray and surface normal) to the nearest IR surface; distance inf if none."""
        dist = mujoco.mj_ray(self.model, self.data, origin, direction, self._ray_mask, 1, -1, self._geomid,
                             self._normal)
        if dist < 0:
            return math.inf, 0.0
        return dist, abs(float(direction @ self._normal))

    def read_ir(self) -> tuple[list[int], list[int]]:
        """(emitter-off, emitter-on) ADC counts of the eight sensors now."""
        s, c = self.spec, self.spec.ir
        x, y, phi = self._ir_pose()
        origin = np.array([x, y, RAY_HEIGHT])
        noise = self.rng.standard_normal(2 * N_SENSORS) * float(c["noise"])
        amb_off = self._ambient(x, y, phi, self.t)
        amb_on = self._ambient(x, y, phi, self.t + float(c["on_delay"]))
        adc_max = float(c["adc_max"]) if s.adc_clip <= 0 else min(float(c["adc_max"]), s.adc_clip)
        off, on = [], []
        r = s.body_radius
        for i in range(N_SENSORS):
            mount = phi + i * math.pi / 4  # where the pair sits on the rim; a misaligned one looks elsewhere
            bearing = mount + s.ir_misalignment[i]
            direction = np.array([math.cos(bearing), math.sin(bearing), 0.0])
            behind = origin + r * np.array([math.cos(mount) - direction[0], math.sin(mount) - direction[1], 0.0])
            dist, cos = self._ray(behind, direction)
            gap = max(0.0, dist - r)  # from the mount, along the turned axis
            angle = math.acos(min(1.0, cos))
            light = self._optics.reflected(gap, angle, self.emitter_pct, float(c["gain"]) * s.ir_gain_scale[i], c)
            if self.emitter_pct > 0:
                light += s.ir_offset[i]  # the emitter pulse couples into the receiver
            v_off = amb_off[i] + noise[i]
            v_on = amb_on[i] * (1.0 + s.ambient_leakage[i]) + light + noise[N_SENSORS + i]
            off.append(int(min(max(round(v_off), 0), adc_max)))
            on.append(int(min(max(round(v_on), 0), adc_max)))
        return off, on

    def _ambient(self, x: float, y: float, phi: float, t: float) -> list[float]:
        """Ambient light (counts) at each sensor: the global level plus the lamps C can see."""
        w = self.world
        base = float(self.spec.ir["ambient"]) if w is None or w.ambient is None else w.ambient
        levels = [base] * N_SENSORS
        if w is None:
            return levels
        r = self.spec.body_radius
        for lamp in w.lamps:
            level = lamp.level * (1.0 + lamp.flicker_depth * math.sin(2 * math.pi * lamp.flicker_hz * t)) \
                if lamp.flicker_hz else lamp.level
            to_lamp = np.array([lamp.x - x, lamp.y - y, 0.0])
            d_lamp = float(np.linalg.norm(to_lamp))
            if d_lamp > 0:
                hit, _ = self._ray(np.array([x, y, RAY_HEIGHT]), to_lamp / d_lamp)
                if hit < d_lamp:
                    continue  # a wall hides it
            for i in range(N_SENSORS):
                mount = phi + i * math.pi / 4
                b = mount + self.spec.ir_misalignment[i]
                axis = (math.cos(b), math.sin(b))
                at = (x + r * math.cos(mount), y + r * math.sin(mount))
                levels[i] += self._optics.lamp_light(level, at, axis, (lamp.x, lamp.y))
        return levels
