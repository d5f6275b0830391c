"""The IR proximity ring of the paper (section 3.3): emitter/phototransistor pairs on the rim (ir_bearings; eight).

Reflected light = C P(L) A(angle) F(x) along each sensor's axis (or its beam), plus the ambient light
of the world and its lamps, noise and the ADC.  `read_sensors` reads one robot (pose (3,)) or N
(poses (N, 3)); `PoseHistory` and read_sensors(track=True) give the readings an ir_latency.  The IR
effects of the library (gain, misalignment, offset, leakage, latency) act here too.
Model, figures and derivation: docs/ir-sensor.md; the effects: docs/effects.md.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from host_sim.physics.params import DEFAULT, RobotParams
from host_sim.physics.world import World

N_SENSORS = 8  # the firmware's ring (the default ir_bearings); a robot's own ring: len(p.ir_bearings)
BEARINGS = tuple(i * math.pi / 4 for i in range(N_SENSORS))  # rad from the heading, S1..S8
NAMES = tuple(f"S{i + 1}" for i in range(N_SENSORS))
LAMP_MIN_DISTANCE = 0.10  # m: a lamp closer than this counts as this far (no 1/d^2 blow-up)
RANGE_TAPER = 0.2  # fraction of sensor_range over which the response fades to 0

# --------------------------------------------------------------------------- #
# Fig. 7: the target angle shape and the fit of the two domes
# --------------------------------------------------------------------------- #
# White matte paper: a broad diffuse dome ~ cos^k(angle) (Lambert's law for
# the emitter spot, a little narrower from the cones' overlap), with the
# residual the paper measured at grazing incidence, plus a narrow specular
# beam on top near normal incidence.  Normalised to 1 at 0.
ANGLE_TARGET = {
    "diffuse_exponent": 1.5,  # k
    "grazing_floor": 0.02,  # the residual at +-pi/2
    "specular_height": 0.20,  # the small dome's share of the peak
    "specular_width": 0.12,  # rad, Gaussian standard deviation (about 7 degrees)
}


def angle_target(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(big dome alone, big + small dome) of the target shape at |angle| (rad)."""
    a = np.abs(np.asarray(angle, dtype=float))
    k, floor = ANGLE_TARGET["diffuse_exponent"], ANGLE_TARGET["grazing_floor"]
    h, w = ANGLE_TARGET["specular_height"], ANGLE_TARGET["specular_width"]
    big = (1.0 - h - floor) * np.cos(np.minimum(a, math.pi / 2)) ** k + floor
    return big, big + h * np.exp(-0.5 * (a / w) ** 2)


def _fit_even_start(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares degree-5 polynomial, coefficients x^0..x^5, with the x^1 term held at 0.

    numpy.polyfit's fit with one constraint: a zero slope at 0 keeps the
    symmetric extension A(|angle|) smooth at normal incidence.
    """
    vander = np.stack([x ** 0, x ** 2, x ** 3, x ** 4, x ** 5], 1)
    c, *_ = np.linalg.lstsq(vander, y, rcond=None)
    return np.array([c[0], 0.0, c[1], c[2], c[3], c[4]])


def fit_angle_polynomials(blend: tuple[float, float] = (0.25, 0.45)
                          ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Fit the two domes to `angle_target`: (big, small) coefficients x^0..x^5.

    The big dome fits the diffuse part on [0, pi/2]; the small dome fits the
    whole shape (diffuse + specular) on [0, blend[1] + 0.05], where it is
    used.  These are the defaults of ir_big_dome / ir_small_dome.
    """
    x_big = np.linspace(0.0, math.pi / 2, 400)
    x_small = np.linspace(0.0, blend[1] + 0.05, 300)
    big = _fit_even_start(x_big, angle_target(x_big)[0])
    small = _fit_even_start(x_small, angle_target(x_small)[1])
    return tuple(float(f"{v:.6g}") for v in big), tuple(float(f"{v:.6g}") for v in small)


# --------------------------------------------------------------------------- #
# The model
# --------------------------------------------------------------------------- #
class _Consts:
    """Per-parameter-set constants, computed once."""

    def __init__(self, p: RobotParams) -> None:
        check_params(p)
        self.p = p
        self.coef = np.array([p.ir_big_dome, p.ir_small_dome]).T  # (6, 2)
        # [small, big - small]: A = small + w (big - small) from one product
        self.coef_blend = np.array([p.ir_small_dome, np.subtract(p.ir_big_dome, p.ir_small_dome)]).T
        self.blend_lo, self.blend_hi = p.ir_angle_blend
        self.inv_blend = 1.0 / (self.blend_hi - self.blend_lo)
        xp = p.ir_near_peak
        self.inv_xp = 1.0 / xp
        self.inv_xp2 = 1.0 / xp ** 2
        self.ln_k = math.log(p.ir_blend)
        self.inv_2ln_k = 0.5 / self.ln_k
        self.range = p.sensor_range
        self.inv_taper = 1.0 / (RANGE_TAPER * p.sensor_range)
        self.adc_max = p.adc_max
        self.powers = np.arange(6.0)
        self.beam_n, off, self.beam_w = beam(p)
        self.beam_w_list = self.beam_w.tolist()
        self.reach = p.sensor_range + p.body_radius
        self._effects(p, off.tolist())

    def _effects(self, p: RobotParams, beam_offsets: list[float]) -> None:
        """The per-pair effects (host_sim/physics/effects.py); None where absent, so the reading skips them."""
        r = p.body_radius
        self.bearings = tuple(p.ir_bearings)  # the pairs' mounts on the rim
        self.bearing_array = np.array(self.bearings)
        self.n = len(self.bearings)
        self.misaligned = any(d != 0.0 for d in p.ir_misalignment)
        self.axis_bearings = tuple(b + d for b, d in zip(self.bearings, p.ir_misalignment))  # turned axes
        self.ray_bearings = tuple(a + o for a in self.axis_bearings for o in beam_offsets)  # sensor-major
        self.axis_origins: tuple[tuple[float, float], ...] | None = None
        self.ray_origins: tuple[tuple[float, float], ...] | None = None
        self.r_cos = [r] * self.n  # body_radius * cos(misalignment): the mount's distance along the axis
        if self.misaligned:
            # A pair turns about its mount on the rim: its rays start r (u_mount - u_axis) from the
            # centre, so that a ray's length minus r is still the distance from the sensor.
            self.axis_origins = tuple((r * (math.cos(b) - math.cos(a)), r * (math.sin(b) - math.sin(a)))
                                      for b, a in zip(self.bearings, self.axis_bearings))
            self.ray_origins = tuple(o for o in self.axis_origins for _ in beam_offsets)
            self.r_cos = [r * math.cos(d) for d in p.ir_misalignment]
        self.r_cos_col = np.array(self.r_cos)[:, None]
        self.gain_scale = None if all(g == 1.0 for g in p.ir_gain_scale) else list(p.ir_gain_scale)
        self.offset = None if all(o == 0.0 for o in p.ir_offset) else list(p.ir_offset)
        self.leakage = None if all(k == 0.0 for k in p.ambient_leakage) else list(p.ambient_leakage)


_CACHE: dict[int, _Consts] = {}


def _consts(p: RobotParams) -> _Consts:
    c = _CACHE.get(id(p))
    if c is None or c.p is not p:
        if len(_CACHE) > 64:
            _CACHE.clear()
        c = _CACHE[id(p)] = _Consts(p)
    return c


def beam(p: RobotParams) -> tuple[int, np.ndarray, np.ndarray]:
    """(n, offsets from the sensor axis (rad), weights summing to 1) of each sensor's rays.

    One ray: along the axis, weight 1 (the default).  n rays: evenly over
    +-ir_beam_half_angle, weights proportional to cos^2(offset).
    """
    n = int(p.ir_beam_rays)
    if n == 1:
        return 1, np.zeros(1), np.ones(1)
    off = np.linspace(-p.ir_beam_half_angle, p.ir_beam_half_angle, n)
    w = np.cos(off) ** 2
    return n, off, w / w.sum()


def check_params(p: RobotParams) -> None:
    """ValueError if the IR parameters cannot make a sensor."""
    problems = []
    if not p.ir_near_peak > 0:
        problems.append(f"ir_near_peak must be > 0 m, got {p.ir_near_peak}")
    if not p.ir_blend > 1:
        problems.append(f"ir_blend (a ratio) must be > 1, got {p.ir_blend}")
    elif not p.sensor_range > p.ir_near_peak * p.ir_blend / (1 - RANGE_TAPER):
        problems.append("sensor_range must reach well beyond ir_near_peak * ir_blend")
    if not 0 < p.ir_saturation <= 1:
        problems.append(f"ir_saturation must be in (0, 1], got {p.ir_saturation}")
    lo, hi = p.ir_angle_blend
    if not 0 <= lo < hi <= math.pi / 2:
        problems.append(f"ir_angle_blend must satisfy 0 <= lo < hi <= pi/2, got {p.ir_angle_blend}")
    if p.ir_gain < 0 or p.ir_noise < 0 or p.ir_ambient < 0 or p.ir_on_delay < 0:
        problems.append("ir_gain, ir_noise, ir_ambient and ir_on_delay must be >= 0")
    if len(p.ir_big_dome) != 6 or len(p.ir_small_dome) != 6:
        problems.append("ir_big_dome and ir_small_dome need 6 coefficients (x^0..x^5)")
    if not (p.ir_beam_rays >= 1 and p.ir_beam_rays == int(p.ir_beam_rays)):
        problems.append(f"ir_beam_rays must be a whole number >= 1, got {p.ir_beam_rays}")
    elif p.ir_beam_rays > 1 and not 0 < p.ir_beam_half_angle < math.pi / 2:
        problems.append(f"ir_beam_half_angle must be in (0, pi/2) rad, got {p.ir_beam_half_angle}")
    problems += _effect_problems(p)
    if problems:
        raise ValueError("IR sensor parameters: " + "; ".join(problems))


def _effect_problems(p: RobotParams) -> list[str]:
    problems = []
    n = len(p.ir_bearings)
    if n < 1:
        problems.append("ir_bearings needs one bearing at least")
    for name in ("ir_gain_scale", "ir_misalignment", "ir_offset", "ambient_leakage"):
        if len(getattr(p, name)) != n:
            problems.append(f"{name} needs {n} values, one per sensor (ir_bearings)")
    if any(g < 0 for g in p.ir_gain_scale):
        problems.append(f"ir_gain_scale must be >= 0, got {p.ir_gain_scale}")
    if any(not abs(d) < math.pi / 2 for d in p.ir_misalignment):
        problems.append(f"ir_misalignment must be within +-pi/2 rad, got {p.ir_misalignment}")
    if not 0 <= p.ir_latency <= 1.0:
        problems.append(f"ir_latency must be in 0..1 s, got {p.ir_latency}")
    return problems


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.minimum(np.maximum(u, 0.0), 1.0)  # np.clip is several times slower on small arrays
    return u * u * (3.0 - 2.0 * u)


def _smootherstep(u: np.ndarray) -> np.ndarray:
    """6u^5 - 15u^4 + 10u^3 on [0, 1]: the blend weight with continuous curvature."""
    u = np.minimum(np.maximum(u, 0.0), 1.0)
    return u * u * u * (u * (6.0 * u - 15.0) + 10.0)


def domes(angle: ArrayLike, p: RobotParams = DEFAULT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(big dome, small dome, blend weight of the big dome) at |angle| (rad)."""
    c = _consts(p)
    a = np.abs(np.asarray(angle, dtype=float))
    v = a[..., None] ** c.powers @ c.coef
    return v[..., 0], v[..., 1], _smoothstep((a - c.blend_lo) * c.inv_blend)


def angle_term(angle: ArrayLike, p: RobotParams = DEFAULT) -> np.ndarray:
    """A(angle): relative response to a wall seen at `angle` (rad) from its normal; A(0) ~ 1."""
    c = _consts(p)
    a = np.abs(np.asarray(angle, dtype=float))
    cs, cd = c.coef_blend[:, 0], c.coef_blend[:, 1]  # small, big - small
    vs = cs[5] * a + cs[4]  # Horner: faster than powers for large batches
    vd = cd[5] * a + cd[4]
    for k in (3, 2, 1, 0):
        vs = vs * a + cs[k]
        vd = vd * a + cd[k]
    w = _smoothstep((a - c.blend_lo) * c.inv_blend)
    return np.maximum(vs + w * vd, 0.0)


def distance_term(distance: ArrayLike, p: RobotParams = DEFAULT) -> np.ndarray:
    """F(x) in 1/m^2: x^2/x_p^4 near, 1/x^2 far, averaged in between; 0 beyond sensor_range.

    Between x_p/k and k x_p (k = ir_blend) the two laws are averaged
    geometrically, the far law's weight s rising as a smootherstep of ln x:
    F = near^(1-s) far^s = x_p^-2 (x/x_p)^(2 - 4 s).  Smooth everywhere,
    maximum 1/x_p^2 at x_p.
    """
    c = _consts(p)
    x = np.maximum(np.minimum(distance, c.range), 1e-6)  # inf (no wall) -> range -> 0
    lx = np.log(x * c.inv_xp)
    s = _smootherstep((lx + c.ln_k) * c.inv_2ln_k)
    f = c.inv_xp2 * np.exp(lx * (2.0 - 4.0 * s))
    u = np.minimum((c.range - x) * c.inv_taper, 1.0)  # >= 0 already
    return f * (u * u * (3.0 - 2.0 * u))


def power_term(power_pct: ArrayLike, p: RobotParams = DEFAULT) -> float | np.ndarray:
    """P(L): light emitted at pulse width L (%), as a fraction of full: proportional, then flat."""
    if isinstance(power_pct, (int, float)):
        return min(max(power_pct / 100.0, 0.0), p.ir_saturation)
    return np.minimum(np.maximum(np.asarray(power_pct, dtype=float) / 100.0, 0.0), p.ir_saturation)


def response(distance: ArrayLike, angle: ArrayLike, power_pct: ArrayLike, p: RobotParams = DEFAULT) -> np.ndarray:
    """Reflected light (ADC counts, before noise and the ADC ceiling) of a wall at
    `distance` (m, along the sensor axis; inf = nothing) seen at `angle` (rad)
    with the emitters at `power_pct` (%).  Vectorised; arguments broadcast."""
    return (p.ir_gain * power_term(power_pct, p)) * angle_term(angle, p) * distance_term(distance, p)


# --------------------------------------------------------------------------- #
# Geometry of the ring
# --------------------------------------------------------------------------- #
def sensor_axes(poses: ArrayLike, p: RobotParams = DEFAULT) -> tuple[np.ndarray, np.ndarray]:
    """(mounts, axes), unit vectors (..., S, 2) of robots at poses (..., 3), S = len(p.ir_bearings).

    Sensor k sits on the rim at C + body_radius * mounts[k] (ir_bearings[k];
    45 k degrees on the firmware's ring) and looks along axes[k]: its mount
    direction turned by ir_misalignment[k] (the same array when no pair is
    misaligned).
    """
    q = np.asarray(poses, dtype=float)
    c = _consts(p)
    mounts = _unit(q[..., 2:3] + c.bearing_array)
    return mounts, (_unit(q[..., 2:3] + np.array(c.axis_bearings)) if c.misaligned else mounts)


def _unit(ang: np.ndarray) -> np.ndarray:
    out = np.empty(ang.shape + (2,))
    out[..., 0] = np.cos(ang)
    out[..., 1] = np.sin(ang)
    return out


def reflection(world: World, poses: ArrayLike, p: RobotParams = DEFAULT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance from the sensor (m), incidence angle (rad), hit) along each sensor's axis, shape (..., 8).

    The ray leaves the robot's centre along the sensor's axis (a misaligned
    pair's ray starts where its turned axis passes one body radius behind
    its mount); the distance from the sensor is its length minus
    body_radius, at least 0 (a wall pushed into the rim touches the sensor).
    """
    c = _consts(p)
    q = np.asarray(poses, dtype=float)
    if q.ndim == 1:
        d, a, h = world.cast_robot(float(q[0]), float(q[1]), float(q[2]), c.axis_bearings, c.reach, c.axis_origins)
    else:
        d, a, h = world.cast_robots(q, c.axis_bearings, c.reach, c.axis_origins)
    return np.maximum(d - p.body_radius, 0.0), a, h


# --------------------------------------------------------------------------- #
# Readings, N robots (numpy)
# --------------------------------------------------------------------------- #
def _quantise(v: np.ndarray, adc_max: int) -> np.ndarray:
    """Round half to even, clip to 0..adc_max: the ADC's integer counts."""
    return np.minimum(np.maximum(np.rint(v), 0.0), adc_max).astype(np.int64)


def _reflected_batch(world: World, poses: np.ndarray, power_pct: ArrayLike, p: RobotParams, c: _Consts) -> np.ndarray:
    """Reflected light (counts) of every sensor, (N, 8): response along its axis, or its beam's weighted sum."""
    if c.beam_n == 1:
        dist, ang, _hit = reflection(world, poses, p)
        refl = response(dist, ang, power_pct, p)
    else:  # the beam: n rays per sensor, the weighted sum of their reflections
        d, ang, _hit = world.cast_robots(poses, c.ray_bearings, c.reach, c.ray_origins)
        shape = poses.shape[:-1] + (c.n, c.beam_n)
        power = np.asarray(power_pct, dtype=float)
        rays = response(np.maximum(d - p.body_radius, 0.0).reshape(shape), ang.reshape(shape),
                        power[..., None] if power.ndim else power, p)
        refl = rays @ c.beam_w
    return refl if c.gain_scale is None else refl * np.array(c.gain_scale)


def _robot_lamp_gains(world: World, poses: np.ndarray, p: RobotParams, c: _Consts) -> np.ndarray:
    """Per sensor and lamp, max(0, cos(axis, to lamp)) / max(d, LAMP_MIN_DISTANCE)^2 (1/m^2): (..., 8, n_lamps).

    Sensor k sits at C + R u_k and looks along a_k (u_k turned by its
    misalignment); with v = lamp - C, a_k . (lamp - sensor) = a_k . v -
    R cos(misalignment) and |lamp - sensor|^2 = |v|^2 - 2 R u_k . v + R^2:
    one product for all.  The line of sight is tested from the robot's
    centre: 8 times fewer tests, the same answer but at a shadow's edge.
    """
    mounts, axes = sensor_axes(poses, p)
    centre = poses[..., :2]
    vx = world.lamp_xy[:, 0] - centre[..., 0:1]  # (..., L)
    vy = world.lamp_xy[:, 1] - centre[..., 1:2]
    dot = mounts[..., 0:1] * vx[..., None, :] + mounts[..., 1:2] * vy[..., None, :]  # (..., 8, L)
    r = p.body_radius
    d2 = np.maximum((vx * vx + vy * vy)[..., None, :] - 2.0 * r * dot + r * r, 1e-24)
    if c.misaligned:
        facing = axes[..., 0:1] * vx[..., None, :] + axes[..., 1:2] * vy[..., None, :] - c.r_cos_col
    else:
        facing = dot - r
    g = np.maximum(facing, 0.0) / (np.sqrt(d2) * np.maximum(d2, LAMP_MIN_DISTANCE ** 2))
    if world.n_walls:
        g = g * world.lamps_visible(centre)[..., None, :]
    return g


def room_ambient(world: World, p: RobotParams) -> float:
    """The ambient light (counts) every sensor sees before any lamp: the world's level, else the robot's."""
    return p.ir_ambient if world.ambient is None else world.ambient


def _ambient_batch(world: World, poses: np.ndarray, t: ArrayLike, p: RobotParams, c: _Consts
                   ) -> tuple[float | np.ndarray, float | np.ndarray]:
    """(ambient at the emitter-off reading, at the emitter-on one): the world's level plus the lamps."""
    base = room_ambient(world, p)
    if not world.lamps:
        return base, base
    gains = _robot_lamp_gains(world, poses, p, c)
    t_arr = np.asarray(t, dtype=float)  # scalar, or one time per robot
    amb_off = base + (gains * world.lamp_levels(t_arr)[..., None, :]).sum(-1)
    if not world.flickers:
        return amb_off, amb_off
    return amb_off, base + (gains * world.lamp_levels(t_arr + p.ir_on_delay)[..., None, :]).sum(-1)


def _read(world: World, poses: np.ndarray, power_pct: ArrayLike, t: ArrayLike, p: RobotParams,
          rng: np.random.Generator | None, quantise: bool = True) -> tuple[np.ndarray, np.ndarray]:
    c = _consts(p)
    refl = _reflected_batch(world, poses, power_pct, p, c)
    amb_off, amb_on = _ambient_batch(world, poses, t, p, c)
    off = amb_off + np.zeros_like(refl)
    on = amb_on + refl
    if c.leakage is not None:  # the emitter-on reading sees more of the ambient light
        on = on + np.array(c.leakage) * amb_on
    if c.offset is not None:  # the emitter pulse coupling into the receiver
        on = on + np.array(c.offset)
    if rng is not None and p.ir_noise > 0:
        noise = rng.standard_normal((2,) + refl.shape) * p.ir_noise
        off = off + noise[0]
        on = on + noise[1]
    if not quantise:
        return np.clip(off, 0.0, c.adc_max), np.clip(on, 0.0, c.adc_max)
    return _quantise(off, c.adc_max), _quantise(on, c.adc_max)


# --------------------------------------------------------------------------- #
# Readings, one robot (plain floats: eight values are too few for numpy)
# --------------------------------------------------------------------------- #
def _reflected_one(c: _Consts, dist: list[float], ang: list[float], gain: float, r: float) -> list[float]:
    """response() of every ray, from the ray lengths (from the centre) and incidence angles: the same formulas."""
    s0, s1, s2, s3, s4, s5 = c.coef_blend[:, 0].tolist()  # small dome
    d0, d1, d2_, d3, d4, d5 = c.coef_blend[:, 1].tolist()  # big - small
    lo, inv_blend = c.blend_lo, c.inv_blend
    rng_x, ln_k, inv_2ln_k, inv_xp, inv_xp2, inv_taper = c.range, c.ln_k, c.inv_2ln_k, c.inv_xp, c.inv_xp2, c.inv_taper
    log, exp = math.log, math.exp
    refl = []
    for d, a in zip(dist, ang):
        xd = d - r
        if not xd < rng_x or gain == 0.0:  # nothing within range (inf included)
            refl.append(0.0)
            continue
        if xd < 1e-6:
            xd = 1e-6
        lx = log(xd * inv_xp)
        u = (lx + ln_k) * inv_2ln_k
        u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
        sw = u * u * u * (u * (6.0 * u - 15.0) + 10.0)
        f = inv_xp2 * exp(lx * (2.0 - 4.0 * sw))
        u = (rng_x - xd) * inv_taper
        if u > 1.0:
            u = 1.0
        f = f * (u * u * (3.0 - 2.0 * u))
        a = -a if a < 0.0 else a
        vs = ((((s5 * a + s4) * a + s3) * a + s2) * a + s1) * a + s0
        if a <= lo:
            va = vs
        else:
            vd = ((((d5 * a + d4) * a + d3) * a + d2_) * a + d1) * a + d0
            u = (a - lo) * inv_blend
            if u > 1.0:
                u = 1.0
            va = vs + (u * u * (3.0 - 2.0 * u)) * vd
        refl.append(gain * (va if va > 0.0 else 0.0) * f)
    return refl


def _ambient_one(world: World, x: float, y: float, phi: float, t: float, p: RobotParams,
                 c: _Consts) -> tuple[list[float], list[float]]:
    """_ambient_batch for one robot: (off, on) per sensor."""
    base = room_ambient(world, p)
    amb_off = [base] * c.n
    if not world.lamps:
        return amb_off, amb_off
    seen = world.lamps_visible(np.array([x, y])).tolist()
    levels_off = np.asarray(world.lamp_levels(t)).tolist()
    levels_on = np.asarray(world.lamp_levels(t + p.ir_on_delay)).tolist() if world.flickers else levels_off
    amb_on = list(amb_off) if world.flickers else amb_off
    mounts = [(math.cos(phi + b), math.sin(phi + b)) for b in c.bearings]
    axes = [(math.cos(phi + a), math.sin(phi + a)) for a in c.axis_bearings] if c.misaligned else None
    r, r_cos, dmin2 = p.body_radius, c.r_cos, LAMP_MIN_DISTANCE ** 2
    for (lx, ly), vis, lev_off, lev_on in zip(world.lamp_xy.tolist(), seen, levels_off, levels_on):
        if not vis:
            continue
        vx, vy = lx - x, ly - y
        v2 = vx * vx + vy * vy
        for k, (ux, uy) in enumerate(mounts):
            dot = ux * vx + uy * vy
            facing = (dot if axes is None else axes[k][0] * vx + axes[k][1] * vy) - r_cos[k]
            if facing <= 0.0:
                continue
            d2 = v2 - 2.0 * r * dot + r * r
            g = facing / (math.sqrt(d2 if d2 > 1e-24 else 1e-24) * (d2 if d2 > dmin2 else dmin2))
            amb_off[k] += lev_off * g
            if amb_on is not amb_off:
                amb_on[k] += lev_on * g
    return amb_off, amb_on


def _counts_one(c: _Consts, amb_off: list[float], amb_on: list[float], refl: list[float],
                rng: np.random.Generator | None, noise_sd: float) -> tuple[list[int], list[int]]:
    """_read's last step for one robot: effects on the on-reading, noise, rounding, the ADC's range."""
    on = [a + v for a, v in zip(amb_on, refl)]
    if c.leakage is not None:
        on = [v + k * a for v, k, a in zip(on, c.leakage, amb_on)]
    if c.offset is not None:
        on = [v + o for v, o in zip(on, c.offset)]
    top = c.adc_max
    if rng is not None and noise_sd > 0:
        noise = (rng.standard_normal(2 * c.n) * noise_sd).tolist()
        off_i = [round(a + e) for a, e in zip(amb_off, noise)]
        on_i = [round(v + e) for v, e in zip(on, noise[c.n:])]
    else:
        off_i = [round(a) for a in amb_off]
        on_i = [round(v) for v in on]
    return ([v if 0 <= v <= top else (0 if v < 0 else top) for v in off_i],
            [v if 0 <= v <= top else (0 if v < 0 else top) for v in on_i])


def _read_one(world: World, x: float, y: float, phi: float, power_pct: float, t: float, p: RobotParams,
              rng: np.random.Generator | None) -> tuple[list[int], list[int]]:
    """read_sensors for one robot, as two lists of Python ints: the simulator's per-cycle hot path.

    The same formulas as _read in plain floats after the ray cast; the two
    agree to the last bit or, in a rare rounding tie of the beam's sum,
    1 count (tests/test_ir_sensor.py::test_beam_batch_equals_single).
    """
    c = _consts(p)
    dist, ang, _hit = world.cast_robot(x, y, phi, c.ray_bearings, c.reach, c.ray_origins)
    refl = _reflected_one(c, dist.tolist(), ang.tolist(), p.ir_gain * float(power_term(power_pct, p)), p.body_radius)
    if c.beam_n > 1:  # the beam: the weighted sum of each sensor's rays
        n, w = c.beam_n, c.beam_w_list
        refl = [sum(w[j] * refl[k * n + j] for j in range(n)) for k in range(c.n)]
    if c.gain_scale is not None:
        refl = [v * g for v, g in zip(refl, c.gain_scale)]
    amb_off, amb_on = _ambient_one(world, x, y, phi, t, p, c)
    return _counts_one(c, amb_off, amb_on, refl, rng, p.ir_noise)


# --------------------------------------------------------------------------- #
# Latency: the readings describe the pose of ir_latency ago
# --------------------------------------------------------------------------- #
def pose_at(times: ArrayLike, poses: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Poses at time(s) t, linear between the samples of a track: times (K,) increasing, poses (K, ..., 3).

    Clamped to the first and last sample (a robot stood where it started);
    the heading takes the short way round.  t scalar: poses[0].shape; t
    (M,): (M, ...) + (3,).
    """
    ts = np.asarray(times, dtype=float)
    q = np.asarray(poses, dtype=float)
    tq = np.asarray(t, dtype=float)
    if len(ts) == 1:
        return np.broadcast_to(q[0], tq.shape + q.shape[1:]).copy()
    i = np.clip(np.searchsorted(ts, tq, side="right") - 1, 0, len(ts) - 2)
    span = ts[i + 1] - ts[i]
    w = np.clip((tq - ts[i]) / np.where(span > 0, span, 1.0), 0.0, 1.0)
    p0 = q[i]
    d = q[i + 1] - p0
    d[..., 2] -= 2 * math.pi * np.round(d[..., 2] / (2 * math.pi))
    return p0 + w.reshape(w.shape + (1,) * (p0.ndim - w.ndim)) * d


class PoseHistory:
    """The poses of one robot (3,) or N robots (N, 3) at their last control instants, for ir_latency.

    A simulator adds the pose at every reading; `at(t)` interpolates
    (pose_at) between them, so every path - SimRobot.sense,
    BatchSim.read_sensors, read_sensors(track=True) on a recorded track - reads
    the same past pose.  Keeps `keep` seconds of them.
    """

    def __init__(self, keep: float) -> None:
        self.keep = float(keep)
        self.t: list[float] = []
        self.poses: list[np.ndarray] = []

    def add(self, t: float | np.ndarray, pose: ArrayLike) -> None:
        """t: the instant, or (N,) each robot's own (robots that live their own durations)."""
        if self.t and np.all(t <= self.t[-1]):  # the same instant read again: the newer pose
            self.t.pop()
            self.poses.pop()
        self.t.append(float(t) if np.ndim(t) == 0 else np.array(t, dtype=float))
        self.poses.append(np.array(pose, dtype=float))
        while len(self.t) > 2 and np.all(self.t[1] <= t - self.keep):
            del self.t[0], self.poses[0]

    def at(self, t: float | np.ndarray) -> np.ndarray:
        if all(np.ndim(x) == 0 for x in self.t):
            return pose_at(self.t, self.poses, t)
        poses = np.stack(self.poses)  # (K, N, 3), each robot along its own times
        times = np.stack([np.broadcast_to(x, poses.shape[1:2]) for x in self.t])
        t = np.broadcast_to(t, poses.shape[1:2])
        return np.stack([pose_at(times[:, n], poses[:, n], t[n]) for n in range(poses.shape[1])])


# --------------------------------------------------------------------------- #
# Readings: the one entry point, for one robot or N
# --------------------------------------------------------------------------- #
def read_sensors(world: World, poses: ArrayLike, power_pct: float | np.ndarray = 60.0, t: float | np.ndarray = 0.0,
                 p: RobotParams = DEFAULT, rng: np.random.Generator | None = None, *, quantise: bool = True,
                 track: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(adc_off, adc_on) of one robot at pose (x, y, phi), each (8,), or of N robots at poses (N, 3), each (N, 8).

    off = ambient + noise; on = ambient (ir_on_delay later) + reflected +
    noise; each clipped to 0..adc_max and rounded (half to even) to int64
    counts, S1..S8.  power_pct (%) and t (s): scalars, or (N,) arrays, one
    per robot.  rng: a numpy Generator for the noise (None = no noise); it
    draws 16 normals per robot, off then on.  quantise=False: the light
    before the ADC rounds it (floats within its range), smooth in the
    parameters: what a fit compares.  The poses are the ones the readings
    describe (ir_latency is the caller's: PoseHistory), except with
    track=True: poses (K, 3) are one robot's track at times t (K,), and row
    j is read at t[j] - ir_latency at the track's pose then (pose_at).
    """
    q = np.asarray(poses, dtype=float)
    if q.ndim not in (1, 2) or q.shape[-1] != 3:
        raise ValueError(f"poses must be one pose (x, y, phi) or (N, 3), got shape {q.shape}")
    if track and p.ir_latency > 0:
        times = np.asarray(t, dtype=float)
        q = pose_at(times, q, times - p.ir_latency)
        t = times - p.ir_latency
    if q.ndim == 1:
        if quantise:  # one robot: plain floats, eight values are too few for numpy
            x, y, phi = q.tolist()
            off, on = _read_one(world, x, y, phi, float(power_pct), float(t), p, rng)
            return np.array(off, dtype=np.int64), np.array(on, dtype=np.int64)
        off_n, on_n = _read(world, q[None], power_pct, t, p, rng, quantise)
        return off_n[0], on_n[0]
    power = np.asarray(power_pct, dtype=float)
    if power.ndim:
        power = power[:, None]
    return _read(world, q, power, t, p, rng, quantise)
