"""The IR sensor model (paper 3.3): shape, calibration, ambient light, noise, ADC."""
from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from host_sim.sensors import ir_sensor as ir
from host_sim.physics.params import DEFAULT as P
from host_sim.physics.world import Lamp as ir_lamp
from host_sim.physics.world import builtin_world, world_from_dict

R = P.body_radius
CEILING = P.adc_max  # 4095


def room(walls, start=(1.0, 1.0, 0.0), **extra):
    data = {"name": "t", "size": [2, 2], "walls": walls, "start": dict(zip(("x", "y", "phi"), start))}
    data.update(extra)
    return world_from_dict(data, "t.json")


def wall_ahead(gap: float, **extra):
    """A long wall across x = 1 + R + gap: S1 of a robot at (1, 1) heading +x sees it `gap` away."""
    x = 1.0 + R + gap
    return room([{"segment": [x, -5, x, 5]}], **extra)


def ambient_reference(world, pose, t=0.0, p=P):
    """The documented ambient of each sensor, straight from its position and axis (docs/ir-sensor.md):
    the world's level plus level(t) max(0, cos(axis, to lamp)) / max(d, 0.1 m)^2 per lamp in sight of the centre."""
    x, y, phi = pose
    level = np.full(8, p.ir_ambient if world.ambient is None else world.ambient, dtype=float)
    for k in range(8):
        b, a = k * math.pi / 4, k * math.pi / 4 + p.ir_misalignment[k]
        sx, sy = x + R * math.cos(phi + b), y + R * math.sin(phi + b)
        for lamp in world.lamps:
            vx, vy = lamp.x - sx, lamp.y - sy
            d = math.hypot(vx, vy)
            cos = (math.cos(phi + a) * vx + math.sin(phi + a) * vy) / d
            if cos > 0 and world.visible(np.array([x, y]), (lamp.x, lamp.y)):
                level[k] += lamp.level_at(t) * cos / max(d, ir.LAMP_MIN_DISTANCE) ** 2
    return level


# --------------------------------------------------------------------------- angle (Fig. 7)
def test_angle_term_symmetric_peaked_and_positive():
    a = np.linspace(0, math.pi / 2, 2001)
    A = ir.angle_term(a)
    assert np.array_equal(A, ir.angle_term(-a))
    assert A.argmax() == 0 and A[0] == pytest.approx(1.0, abs=0.01)
    assert (A > 0).all() and (np.diff(A) <= 1e-12).all()  # falls monotonically towards grazing
    big, small, w = ir.domes(a)
    assert (big > 0).all(), "the big dome must stay positive on [0, pi/2]"
    lo, hi = P.ir_angle_blend
    assert (small[a <= hi] > 0).all()
    assert (w[a <= lo] == 0).all() and (w[a >= hi] == 1).all()
    # The specular small dome stands on the diffuse big one near normal incidence only.
    assert A[0] - big[0] == pytest.approx(0.2, abs=0.01)
    assert np.allclose(A[a >= hi], big[a >= hi])


def test_angle_polynomials_are_the_documented_fit():
    big, small = ir.fit_angle_polynomials(P.ir_angle_blend)
    assert np.allclose(big, P.ir_big_dome, rtol=1e-5, atol=1e-6)
    assert np.allclose(small, P.ir_small_dome, rtol=1e-5, atol=1e-6)
    assert len(P.ir_big_dome) == len(P.ir_small_dome) == 6 and P.ir_big_dome[1] == P.ir_small_dome[1] == 0
    a = np.linspace(0, math.pi / 2, 500)
    assert np.abs(ir.angle_term(a) - ir.angle_target(a)[1]).max() < 0.01


# --------------------------------------------------------------------------- distance (Fig. 8)
def test_distance_peak_near_law_far_law_and_smoothness():
    x = np.linspace(1e-4, 0.1, 100_000)
    F = ir.distance_term(x)
    xp, k = P.ir_near_peak, P.ir_blend
    assert abs(x[F.argmax()] - xp) < 5e-4 and F.max() == pytest.approx(1 / xp ** 2, rel=1e-4)
    far = (x > k * xp) & (x < 0.8 * P.sensor_range)
    assert np.allclose(F[far], 1 / x[far] ** 2, rtol=1e-12)  # C/x^2
    near = x < xp / k
    assert np.allclose(F[near], x[near] ** 2 / xp ** 4, rtol=1e-12)  # D x^2, D = C/x_p^4
    assert ir.distance_term(0.0) < 1e-6 * F.max()  # falls to 0 at contact
    rel_step = np.abs(np.diff(F)) / F[1:]
    assert rel_step.max() < 0.03  # no jump anywhere (0.001 mm grid)
    assert ir.distance_term(np.inf) == 0 and ir.distance_term(P.sensor_range) == 0
    assert ir.distance_term(0.9 * P.sensor_range) < 1 / (0.9 * P.sensor_range) ** 2  # the taper


def test_far_law_is_inverse_square():
    assert ir.response(0.10, 0, 60) / ir.response(0.20, 0, 60) == pytest.approx(4.0, rel=1e-9)


# --------------------------------------------------------------------------- power (Fig. 10)
def test_power_proportional_then_flat():
    L = np.arange(0, 101)
    r = ir.response(0.08, 0.3, L)
    below = (L > 0) & (L <= 100 * P.ir_saturation)
    assert np.allclose(r[below] / L[below], r[10] / 10, rtol=1e-12)
    above = L >= 100 * P.ir_saturation
    assert np.allclose(r[above], r[above][0], rtol=1e-12)
    assert r[0] == 0


# --------------------------------------------------------------------------- calibration
def test_calibration_against_the_firmware_thresholds():
    at = lambda d: float(ir.response(d, 0.0, 60))  # noqa: E731 - white wall straight ahead, L = 60 %
    assert 630 <= at(0.05) <= 770  # firmware NEAR_HI = 700 at ~5 cm
    assert 70 <= at(0.15) <= 100
    assert at(0.25) < 40 and at(0.30) < 40  # below NEAR_LO beyond ~25 cm
    assert at(0.20) > 40
    x = np.linspace(0.001, 0.1, 5000)
    assert 0.01 <= x[ir.response(x, 0, 60).argmax()] <= 0.02  # maximum at 1-2 cm
    assert at(0.001) < 40  # and towards 0 at contact


def test_saturation_close_at_high_power_only():
    off, on = ir.read_sensors(wall_ahead(0.015), (1.0, 1.0, 0.0), 78)
    assert on[0] == CEILING and off[0] == P.ir_ambient
    off, on = ir.read_sensors(wall_ahead(0.015), (1.0, 1.0, 0.0), 27)
    assert on[0] < CEILING
    off, on = ir.read_sensors(wall_ahead(0.05), (1.0, 1.0, 0.0), 100)
    assert on[0] < CEILING


# --------------------------------------------------------------------------- readings
def test_sensor_numbering_and_geometry():
    # Robot at (1, 1) heading +y (phi = pi/2): S1 looks up, S3 left (-x), S7 right (+x).
    w = room([{"segment": [1 + R + 0.04, -5, 1 + R + 0.04, 5]}])  # a wall 4 cm to the right
    off, on = ir.read_sensors(w, (1.0, 1.0, math.pi / 2), 60)
    refl = on - off
    assert refl.argmax() == 6  # S7
    assert refl[6] == round(float(ir.response(0.04, 0.0, 60)))
    assert refl[5] == refl[7] > 0  # S6, S8 at +-45 degrees see it symmetrically
    assert refl[5] == round(float(ir.response(0.04 * math.sqrt(2) + R * (math.sqrt(2) - 1), math.pi / 4, 60)))
    assert (refl[[0, 1, 2, 3, 4]] == 0).all()
    mounts, axes = ir.sensor_axes(np.array([1.0, 1.0, math.pi / 2]))
    assert 1.0 + R * mounts[0] == pytest.approx([1.0, 1.0 + R]) and axes[2] == pytest.approx([-1.0, 0.0])


def test_ambient_adds_to_both_readings():
    w = wall_ahead(0.06, ambient=900)
    off, on = ir.read_sensors(w, (1.0, 1.0, 0.0), 60)
    assert (off == 900).all()
    expected = np.rint(900 + ir.response(*ir.reflection(w, np.array([1.0, 1.0, 0.0]))[:2], 60)) - 900
    assert np.array_equal(on - off, expected)
    assert on[0] - off[0] == round(float(ir.response(0.06, 0, 60)))
    # Without a world level, the parameters' ir_ambient.
    off2, on2 = ir.read_sensors(wall_ahead(0.06), (1.0, 1.0, 0.0), 60)
    assert (off2 == P.ir_ambient).all() and np.array_equal(on2 - off2, on - off)


def test_adc_ceiling_clips_the_total():
    off, on = ir.read_sensors(wall_ahead(0.03, ambient=3500), (1.0, 1.0, 0.0), 60)
    assert on[0] == CEILING and off[0] == 3500  # reflected 1940 + 3500 > 4095
    off, on = ir.read_sensors(wall_ahead(0.03, ambient=5000), (1.0, 1.0, 0.0), 60)
    assert (off == CEILING).all() and (on == CEILING).all()


def test_lamps_position_direction_occlusion_and_flicker():
    lamp = {"x": 1.5, "y": 1.0, "level": 10.0}
    w = room([], lamps=[lamp], ambient=100)
    off, _ = ir.read_sensors(w, (1.0, 1.0, 0.0), 60)
    d = 0.5 - R
    assert off[0] == round(100 + 10 / d ** 2)  # S1 faces the lamp
    assert off[4] == 100 and off[3] == 100  # facing away: nothing
    assert off[1] == round(100 + 10 * (math.cos(math.pi / 4) * 0.5 - R) / (math.hypot(
        0.5 - R * math.cos(math.pi / 4), R * math.sin(math.pi / 4))) ** 3)
    # The lamp term computed sensor by sensor from its position on the rim agrees.
    assert np.array_equal(np.rint(ambient_reference(w, (1.0, 1.0, 0.0))), off)
    # A wall between the robot and the lamp hides it.
    hidden = room([{"segment": [1.3, 0.5, 1.3, 1.5]}], lamps=[lamp], ambient=100)
    assert (ir.read_sensors(hidden, (1.0, 1.0, 0.0), 60)[0] == 100).all()
    # A flickering lamp: the ambient changes from cycle to cycle.
    flick = room([], lamps=[dict(lamp, flicker_hz=100.0, flicker_depth=0.5)], ambient=100)
    levels = {int(ir.read_sensors(flick, (1.0, 1.0, 0.0), 60, t=k * 0.0123)[0][0]) for k in range(10)}
    assert len(levels) >= 5 and min(levels) >= round(100 + 5 / d ** 2) - 1 and max(levels) <= round(
        100 + 15 / d ** 2) + 1


def test_flicker_leaks_into_on_minus_off_through_the_read_delay():
    lamp = {"x": 1.5, "y": 1.0, "level": 10.0, "flicker_hz": 100.0, "flicker_depth": 0.5}
    w = room([], lamps=[lamp], ambient=100)  # nothing to reflect: on - off is pure leakage
    leaks = [int(np.subtract(*ir.read_sensors(w, (1.0, 1.0, 0.0), 60, t=k * 0.0011)[::-1])[0])
             for k in range(20)]
    assert max(map(abs, leaks)) > 3  # amplitude 25.8 counts x 2 pi 100 Hz x 0.4 ms = 6.5
    p0 = P.replace(ir_on_delay=0.0)
    assert all((np.subtract(*ir.read_sensors(w, (1.0, 1.0, 0.0), 60, k * 0.0011, p0)[::-1]) == 0).all()
               for k in range(20))


def test_noise_has_the_configured_std_and_readings_are_integers():
    w = builtin_world("arena")
    rng = np.random.default_rng(42)
    poses = np.tile([1.0, 1.0, 0.3], (4000, 1))
    off, on = ir.read_sensors(w, poses, 60, 0.0, P, rng)
    assert off.dtype.kind == "i" and on.dtype.kind == "i"
    assert off.min() >= 0 and on.max() <= CEILING
    amb = P.ir_ambient
    assert off.mean() == pytest.approx(amb, abs=0.2)
    # Rounding adds 1/12 count^2 of variance.
    assert off.std() == pytest.approx(math.sqrt(P.ir_noise ** 2 + 1 / 12), rel=0.05)
    assert (on - off).std() == pytest.approx(math.sqrt(2 * P.ir_noise ** 2 + 2 / 12), rel=0.05)
    loud = P.replace(ir_noise=40.0)
    off, _ = ir.read_sensors(w, poses[:2000], 60, 0.0, loud, rng)
    assert off.std() == pytest.approx(40.0, rel=0.05)
    # rng None: no noise, the same answer every time.
    a = ir.read_sensors(w, (1.0, 1.0, 0.3), 60)
    b = ir.read_sensors(w, (1.0, 1.0, 0.3), 60)
    assert all(np.array_equal(u, v) for u, v in zip(a, b))


def test_batch_equals_single():
    w = builtin_world("paper_room")
    rng = np.random.default_rng(7)
    poses = np.column_stack([rng.uniform(0.1, 1.9, 64), rng.uniform(0.1, 1.4, 64), rng.uniform(-4, 4, 64)])
    power = rng.uniform(10, 100, 64)
    t = rng.uniform(0, 5, 64)
    off_b, on_b = ir.read_sensors(w, poses, power, t)
    for i in range(64):
        off, on = ir.read_sensors(w, poses[i], float(power[i]), float(t[i]))
        assert np.array_equal(off, off_b[i]) and np.array_equal(on, on_b[i])
    # Somewhere in the room some sensors see walls, and the lamp through the exit lifts some ambient readings.
    assert (on_b - off_b).max() > 200 and off_b.max() > P.ir_ambient
    # Flickering lamps, two of them, and noise: a seed gives the same readings alone or in a batch of one.
    lamps = [{"x": 1.0, "y": 1.3, "level": 30.0, "flicker_hz": 100.0}, {"x": 0.2, "y": 0.2, "level": 20.0}]
    lit = w.with_changes(lamps=tuple(ir_lamp(**lamp) for lamp in lamps))
    for i in range(0, 64, 4):
        single = ir.read_sensors(lit, poses[i], float(power[i]), float(t[i]), P, np.random.default_rng(i))
        batch = ir.read_sensors(lit, poses[i:i + 1], power[i], t[i], P, np.random.default_rng(i))
        assert np.array_equal(single[0], batch[0][0]) and np.array_equal(single[1], batch[1][0])


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="ir_blend"):
        ir.response(0.1, 0, 60, P.replace(ir_blend=0.5))
    with pytest.raises(ValueError, match="ir_angle_blend"):
        ir.response(0.1, 0, 60, P.replace(ir_angle_blend=(0.5, 0.2)))
    with pytest.raises(ValueError, match="pose"):
        ir.read_sensors(builtin_world("arena"), (1.0, 1.0), 60)


# --------------------------------------------------------------------------- tools
def test_plot_sensor_cli_writes_the_figures(tmp_path):
    pytest.importorskip("matplotlib")
    from tools.cli import plot

    parser = argparse.ArgumentParser()
    plot.register(parser.add_subparsers(), "plot", "figures")
    args = parser.parse_args(["plot", "sensor", "--out", str(tmp_path)])
    assert args.func(args) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["fig10_power.png", "fig11_3d_L27.png", "fig12_3d_L78.png", "fig7_angle.png",
                     "fig8_distance.png"]
    assert all((tmp_path / n).stat().st_size > 10_000 for n in names)


def test_bench_reports_timings():
    from tools.bench.sensors import bench

    out = bench(repeats=3, batch=50)
    assert out["read_us"] > 0 and out["batch_reads_per_s"] > 0 and out["ray_cast_us"] > 0


# --------------------------------------------------------------------------- the beam option
BEAM = P.replace(ir_beam_rays=5, ir_beam_half_angle=0.35)


def test_beam_batch_equals_single():
    w = builtin_world("paper_room")
    rng = np.random.default_rng(11)
    poses = np.column_stack([rng.uniform(0.1, 1.9, 64), rng.uniform(0.1, 1.4, 64), rng.uniform(-4, 4, 64)])
    power = rng.uniform(10, 100, 64)
    off_b, on_b = ir.read_sensors(w, poses, power, 0.0, BEAM)
    single = np.array([ir.read_sensors(w, poses[i], float(power[i]), 0.0, BEAM)[1] for i in range(64)])
    assert np.abs(single - on_b).max() <= 1 and (single == on_b).mean() > 0.99  # 1 count at a rounding tie
    assert not np.array_equal(on_b, ir.read_sensors(w, poses, power, 0.0, P)[1])  # the beam is on
    noisy = ir.read_sensors(w, poses[0], 60.0, 0.0, BEAM, np.random.default_rng(3))
    batch = ir.read_sensors(w, poses[:1], 60.0, 0.0, BEAM, np.random.default_rng(3))
    assert np.abs(noisy[1] - batch[1][0]).max() <= 1


def test_beam_sees_a_corner_between_two_sensor_axes():
    """A box corner at 22.5 degrees, between S1 and S2: invisible to single rays, seen by the beam."""
    bearing, reach, half = math.radians(22.5), 0.10, 0.02  # the corner 4 cm from the rim; the box 2 cm half-diagonal
    cx, cy = 1.0 + (reach + half) * math.cos(bearing), 1.0 + (reach + half) * math.sin(bearing)
    corner = [[cx + half * math.cos(bearing + math.pi + k * math.pi / 2), cy + half * math.sin(bearing + math.pi + k * math.pi / 2)]
              for k in range(4)]  # a square whose first corner points back at the robot
    w = room([{"polygon": corner}])
    off, on = ir.read_sensors(w, (1.0, 1.0, 0.0), 60, 0.0, P)
    assert (on - off)[:2].max() == 0  # neither S1's nor S2's axis meets it
    off, on = ir.read_sensors(w, (1.0, 1.0, 0.0), 60, 0.0, BEAM)
    assert (on - off)[0] > 40 and (on - off)[1] > 40  # firmware NEAR_LO: both see an obstacle
    off_b, on_b = ir.read_sensors(w, np.array([[1.0, 1.0, 0.0]]), 60, 0.0, BEAM)
    assert np.abs(on_b[0] - on).max() <= 1


def test_beam_parameters_are_checked():
    with pytest.raises(ValueError, match="ir_beam_rays"):
        ir.response(0.1, 0, 60, P.replace(ir_beam_rays=2.5))
    with pytest.raises(ValueError, match="ir_beam_half_angle"):
        ir.response(0.1, 0, 60, P.replace(ir_beam_rays=3, ir_beam_half_angle=2.0))
