"""Worlds: validation messages, built-ins, ray casting, nearest wall, obstacles, free-space grid."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from host_sim.physics.world import (BUILTIN_NAMES, World, WorldError, builtin_world, load_world, save_world,
                            world_by_name_or_path, world_from_dict)

BOX = [{"segment": [0, 0, 4, 0]}, {"segment": [4, 0, 4, 4]}, {"segment": [4, 4, 0, 4]}, {"segment": [0, 4, 0, 0]}]


def make(walls, start=(2.0, 2.0, 0.0), **extra) -> World:
    data = {"name": "t", "size": [4, 4], "walls": walls, "start": dict(zip("x y phi".split(), start))}
    data.update(extra)
    return world_from_dict(data, "t.json")


def write(tmp_path, name, data) -> str:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return str(path)


def good(**changes):
    data = {"name": "w", "size": [2, 2], "walls": [{"segment": [0, 0, 2, 0]}], "start": {"x": 1, "y": 1, "phi": 0}}
    data.update(changes)
    return data


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize("data, entry, problem", [
    (good(walls=[{"segment": [0, 0, 2, 0]}, {"polygon": [[0, 0], [1, 0]]}]), "walls[1].polygon", "fewer than 3 points"),
    (good(walls=[{"polygon": [[0, 0], [1, 0], [1, 1], [0.8, 0.3], [0, 1]]}]), "walls[0].polygon", "not convex"),
    (good(walls=[{"polygon": [[0, 0], [1, 0], ["a", 1]]}]), "walls[0].polygon[2]", "not a finite number"),
    (good(walls=[{"polygon": [[0, 0], [1, 0], [2, 0]]}]), "walls[0].polygon", "collinear"),
    (good(walls=[{"polygon": [[0, 0], [1, 0], [1, 0], [0, 1]]}]), "walls[0].polygon", "coincide"),
    (good(walls=[{"polygon": [[1 + 0.5 * math.cos(k * 4 * math.pi / 5), 1 + 0.5 * math.sin(k * 4 * math.pi / 5)]
                              for k in range(5)]}], start={"x": 0.2, "y": 1.8, "phi": 0}),
     "walls[0].polygon", "crosses itself"),  # a pentagram turns the same way at every point
    (good(walls=[{"segment": [0, 0, 1]}]), "walls[0].segment", "list of 4 numbers"),
    (good(walls=[{"segment": [0, 0, 1, True]}]), "walls[0].segment", "not a finite number"),
    (good(walls=[{"segment": [1, 1, 1, 1]}]), "walls[0].segment", "degenerate"),
    (good(walls=[{"segment": [0, 0, 1, 0], "colour": "red"}]), "walls[0]", "exactly one key"),
    (good(walls=[{"line": [0, 0, 1, 0]}]), "walls[0]", "'segment' or 'polygon'"),
    (good(gravity=9.81), "unknown key 'gravity'", "allowed"),
    (good(start={"x": 1, "y": 0.03, "phi": 0}), "start", "overlaps (centre 0.030 m from it) walls[0].segment"),
    (good(walls=[{"polygon": [[0.5, 0.5], [1.5, 0.5], [1.5, 1.5], [0.5, 1.5]]}]), "start", "is inside walls[0].polygon"),
    (good(start={"x": 3, "y": 1, "phi": 0}), "start", "outside the world's size"),
    (good(start={"x": 1, "y": 1}), "start", "missing 'phi'"),
    (good(size=[2, -1]), "size", "positive"),
    (good(lamps=[{"x": 1, "y": 1}]), "lamps[0]", "missing 'level'"),
    (good(lamps=[{"x": 1, "y": 1, "level": 5, "flicker_depth": 2}]), "lamps[0].flicker_depth", "[0, 1]"),
    (good(lamps=[{"x": 1, "y": 1, "level": 5, "hue": 2}]), "lamps[0]", "unknown key 'hue'"),
    (good(ambient=-3), "ambient", ">= 0"),
])
def test_bad_files_name_file_entry_problem(tmp_path, data, entry, problem):
    path = write(tmp_path, "bad.json", data)
    with pytest.raises(WorldError) as err:
        load_world(path)
    msg = str(err.value)
    assert msg.startswith(path), msg
    assert entry in msg, msg
    assert problem in msg, msg


def test_missing_key_and_bad_json(tmp_path):
    data = good()
    del data["walls"]
    with pytest.raises(WorldError, match=r"m\.json: missing key 'walls'"):
        load_world(write(tmp_path, "m.json", data))
    with pytest.raises(WorldError, match=r"j\.json: not valid JSON \(line 1, column"):
        load_world(write(tmp_path, "j.json", '{"name": '))
    with pytest.raises(WorldError, match="cannot read"):
        load_world(tmp_path / "absent.json")


def test_clockwise_and_counter_clockwise_polygons_are_accepted(tmp_path):
    square = [[0.2, 0.2], [0.6, 0.2], [0.6, 0.6], [0.2, 0.6]]
    for pts in (square, square[::-1]):
        w = load_world(write(tmp_path, "p.json", good(walls=[{"polygon": pts}])))
        assert w.inside_obstacle(np.array([0.4, 0.4]))
        assert not w.inside_obstacle(np.array([0.7, 0.4]))


def test_builtins_load_and_round_trip(tmp_path):
    sizes = {}
    for name in BUILTIN_NAMES:
        w = builtin_world(name)
        assert w.name == name and w.n_walls >= 4
        assert world_by_name_or_path(name).n_walls == w.n_walls
        path = tmp_path / f"{name}.json"
        save_world(w, path)
        again = load_world(path)
        assert np.array_equal(again.segments, w.segments) and again.start == w.start and again.lamps == w.lamps
        sizes[name] = w.size
    assert sizes["paper_room"] == (2.0, 1.5) and sizes["arena"] == (2.0, 2.0)
    with pytest.raises(WorldError, match="no built-in world 'nowhere'"):
        builtin_world("nowhere")
    with pytest.raises(WorldError, match="neither a built-in world"):
        world_by_name_or_path("nowhere")


def test_paper_room_exit_is_a_robot_wide_gap_to_the_outside():
    w = builtin_world("paper_room")
    # From the start, the robot can reach the exit gap on the right wall and leave the area.
    free = w.free_cells(0.02, margin=0.065, reachable=True)
    ys = w.cell_centres(0.02)[1]
    assert free[(ys > 1.05) & (ys < 1.35)][:, -1].any(), "the exit is not reachable"
    # The exit gap is the only way out: a ray through it leaves, rays elsewhere hit the outer wall.
    d, _, hit = w.ray_cast(np.array([1.9, 1.2]), np.array([1.0, 0.0]))
    assert not hit
    assert w.outside(np.array([2.1, 1.2])) and not w.outside(np.array([1.9, 1.2]))
    gap_ends = [s for s in w.segments if s[0] == s[2] == 2.0]
    ys_ = sorted(v for s in gap_ends for v in (s[1], s[3]))
    assert any(math.isclose(b - a, 0.3) for a, b in zip(ys_[1::2], ys_[2::2]))


def test_maze_corridors_are_two_and_a_half_robot_diameters():
    w = builtin_world("maze")
    for x1, y1, x2, y2 in w.segments:  # walls on a 0.3 m grid
        for v in (x1, y1, x2, y2):
            assert abs(v / 0.3 - round(v / 0.3)) < 1e-9
    assert w.free_cells(0.05, reachable=True).sum() == w.free_cells(0.05).sum()  # every corridor connected


# --------------------------------------------------------------------------- ray casting
def test_perpendicular_wall_at_known_distance():
    w = make(BOX + [{"segment": [3, 1, 3, 3]}])
    d, a, hit = w.ray_cast(np.array([1.0, 2.0]), np.array([1.0, 0.0]))
    assert hit and d == pytest.approx(2.0) and a == pytest.approx(0.0)


def test_wall_at_45_degrees():
    w = make([{"segment": [2, 0, 4, 2]}], start=(1.0, 3.0, 0.0))  # on the line y = x - 2
    dist, _, hit = w.ray_cast(np.array([1.0, 0.0]), np.array([0.0, 1.0]))  # x = 1 meets the line off the wall
    assert not hit
    d1, a1, hit = w.ray_cast(np.array([2.5, 0.0]), np.array([0.0, 1.0]))  # up: meets (2.5, 0.5)
    assert hit and d1 == pytest.approx(0.5) and abs(a1) == pytest.approx(math.pi / 4)
    # Along the normal: incidence 0.
    d, a, hit = w.ray_cast(np.array([2.0, 2.0]), np.array([1.0, -1.0]) / math.sqrt(2))
    assert d == pytest.approx(math.sqrt(2)) and a == pytest.approx(0.0, abs=1e-12)
    # The mirror image of the first ray about the normal: the same |angle|, the other sign.
    d2, a2, hit = w.ray_cast(np.array([3.5, 1.0]), np.array([-1.0, 0.0]))  # left: meets (3, 1)
    assert d2 == pytest.approx(0.5) and a2 == pytest.approx(-a1)
    # Shallower: a ray at 30 degrees from the wall's direction meets it at 60 degrees from the normal.
    u = np.array([math.cos(math.radians(75)), math.sin(math.radians(75))])  # 30 degrees from (1, 1)
    _, a3, hit = w.ray_cast(np.array([3.0, 0.0]), u)
    assert hit and abs(a3) == pytest.approx(math.radians(60))


def test_miss_parallel_and_max_range():
    w = make(BOX[:1], start=(2.0, 2.0, 0.0))  # only the bottom wall y = 0, x in [0, 4]
    for o, d in (([2, 2], [0, 1]), ([2, 2], [1, 0]), ([5, 2], [0, -1]), ([2, 0], [1, 0])):
        dist, a, hit = w.ray_cast(np.array(o, float), np.array(d, float))
        assert not hit and dist == math.inf and a == 0.0
    dist, _, hit = w.ray_cast(np.array([2.0, 2.0]), np.array([0.0, -1.0]), max_range=1.5)
    assert not hit and dist == math.inf
    dist, _, hit = w.ray_cast(np.array([2.0, 2.0]), np.array([0.0, -1.0]), max_range=2.5)
    assert hit and dist == pytest.approx(2.0)
    # Through an end point: a hit.
    dist, _, hit = w.ray_cast(np.array([4.0, 1.0]), np.array([0.0, -1.0]))
    assert hit and dist == pytest.approx(1.0)


def test_nearest_of_two_walls_and_a_polygon():
    w = make(BOX + [{"segment": [3, 0.5, 3, 3.5]}, {"polygon": [[1.5, 2.5], [2.5, 2.5], [2.5, 3.5], [1.5, 3.5]]}],
             start=(1.0, 1.0, 0.0))
    d, _, _ = w.ray_cast(np.array([1.0, 2.0]), np.array([1.0, 0.0]))  # wall at x = 3, then x = 4
    assert d == pytest.approx(2.0)
    d, a, _ = w.ray_cast(np.array([2.0, 1.0]), np.array([0.0, 1.0]))  # polygon's bottom edge at y = 2.5
    assert d == pytest.approx(1.5) and a == pytest.approx(0.0)
    s = 1 / math.sqrt(2)
    d, a, _ = w.ray_cast(np.array([1.0, 1.5]), np.array([s, s]))  # meets the bottom edge at (2, 2.5)
    assert d == pytest.approx(math.sqrt(2)) and abs(a) == pytest.approx(math.pi / 4)
    d, _, _ = w.ray_cast(np.array([2.0, 3.0]), np.array([1.0, 0.0]))  # from inside: the far edge x = 2.5
    assert d == pytest.approx(0.5)


def test_batch_equals_scalar_and_robot_fast_path():
    w = builtin_world("paper_room")
    rng = np.random.default_rng(3)
    n = 600  # 4800 rays x 12 walls: the in-place (workspace) path of _solve
    poses = np.column_stack([rng.uniform(0, 2, n), rng.uniform(0, 1.5, n), rng.uniform(-4, 4, n)])
    bearings = [k * math.pi / 4 for k in range(8)]
    ang = poses[:, 2:3] + np.array(bearings)
    dirs = np.stack([np.cos(ang), np.sin(ang)], -1)
    origins = np.broadcast_to(poses[:, None, :2], (n, 8, 2))
    d, a, h = w.ray_cast(origins, dirs, 1.0)
    assert d.shape == (n, 8)
    dr, ar, hr = w.cast_robots(poses, bearings, 1.0)
    assert np.array_equal(h, hr)
    assert np.allclose(d[h], dr[h], rtol=0, atol=1e-12) and np.allclose(a, ar, atol=1e-12)
    # The small-batch path agrees: the same hits, the same numbers to rounding.  Not
    # bit for bit: BLAS picks other kernels for other matrix shapes, and on some CPUs
    # (OpenBLAS, Haswell) they round the 9-term sums differently in the last bit.
    ds, as_, hs = w.cast_robots(poses[:5], bearings, 1.0)
    assert np.array_equal(hs, hr[:5])
    assert np.allclose(ds[hs], dr[:5][hs], rtol=0, atol=1e-12) and np.allclose(as_, ar[:5], atol=1e-12)
    again = w.cast_robots(poses, bearings, 1.0)  # buffers reused: same answer
    assert all(np.array_equal(u, v) for u, v in zip(again, (dr, ar, hr)))
    for i in range(0, n, 37):
        for k in range(8):
            ds, as_, hs = w.ray_cast(origins[i, k], dirs[i, k], 1.0)
            assert hs == h[i, k] and (ds == d[i, k] or math.isclose(ds, d[i, k])) and as_ == pytest.approx(a[i, k])
        d1, a1, h1 = w.cast_robot(*poses[i], bearings, 1.0)
        assert np.array_equal(h1, h[i]) and np.allclose(np.where(h1, d1, 0), np.where(h[i], d[i], 0))


def test_walls_in_segment_array_include_polygon_edges():
    w = make(BOX + [{"polygon": [[1, 1], [2, 1], [1.5, 1.8]]}], start=(3.0, 3.0, 0.0))
    assert w.segments.shape == (7, 4)
    assert list(w.segment_entry) == [0, 1, 2, 3, 4, 4, 4]


# --------------------------------------------------------------------------- distances, grids
def test_nearest_wall_signed_distance_and_normal():
    w = make(BOX + [{"polygon": [[1, 1], [2, 1], [2, 2], [1, 2]]}], start=(3.0, 3.0, 0.0))
    pts = np.array([[3.0, 0.5], [0.2, 3.0], [1.5, 2.3], [1.5, 1.1], [2.5, 2.5]])
    d, n = w.nearest_wall(pts)
    assert d == pytest.approx([0.5, 0.2, 0.3, -0.1, math.sqrt(0.5)])
    assert n[0] == pytest.approx([0, 1]) and n[1] == pytest.approx([1, 0]) and n[2] == pytest.approx([0, 1])
    assert n[3] == pytest.approx([0, -1])  # inside: still points out of the obstacle
    assert n[4] == pytest.approx([math.sqrt(0.5), math.sqrt(0.5)])  # from the corner
    d, n = w.nearest_wall(np.array([[0.0, 2.0]]))  # on a wall: that wall's normal
    assert d[0] == 0 and np.linalg.norm(n[0]) == pytest.approx(1.0)


def test_inside_obstacle_and_free_cells():
    w = make(BOX + [{"polygon": [[1, 1], [2, 1], [2, 2], [1, 2]]}], start=(3.0, 3.0, 0.0))
    assert list(w.inside_obstacle(np.array([[1.5, 1.5], [2.5, 1.5], [1.0, 1.5]]))) == [True, False, False]
    free = w.free_cells(0.1, margin=0.12)
    assert free.shape == w.grid_shape(0.1) == (40, 40)
    xs, ys = w.cell_centres(0.1)
    gx, gy = np.meshgrid(xs, ys)
    to_box = np.minimum.reduce([gx, 4 - gx, gy, 4 - gy])
    to_square = np.hypot(np.maximum.reduce([1 - gx, gx - 2, 0 * gx]), np.maximum.reduce([1 - gy, gy - 2, 0 * gy]))
    assert np.array_equal(free, (to_box >= 0.12) & (to_square >= 0.12))
    iy, ix = w.cell_of(np.array([3.05, 0.55]), 0.1)
    assert (iy, ix) == (5, 30)


def test_reachable_cells_stop_at_walls():
    # A wall across the box with no gap: the far half is free but not reachable.
    w = make(BOX + [{"segment": [0, 2, 4, 2]}], start=(2.0, 1.0, 0.0))
    free = w.free_cells(0.1, margin=0.1)
    reach = w.free_cells(0.1, margin=0.1, reachable=True)
    ys = w.cell_centres(0.1)[1]
    assert free[ys > 2.2].any() and not reach[ys > 2.2].any() and reach[ys < 1.8].any()


def test_visibility_to_lamps():
    w = make(BOX + [{"segment": [2, 1, 2, 3]}], start=(1.0, 2.0, 0.0))
    seen = w.visible(np.array([[1.0, 2.0], [3.0, 0.5], [3.0, 2.8]]), np.array([[3.0, 2.0], [1.0, 3.5]]))
    assert seen.tolist() == [[False, True], [True, False], [True, True]]
    assert w.visible(np.array([1.0, 2.0]), (3.0, 2.0)).shape == ()
