"""Sensor-model speed: one robot's IR read and a batch of robots, in the paper's room.

`bench()` times the ray cast, one robot's read and a batch's read of
host_sim/sensors/ir_sensor.py; tests/test_ir_sensor.py runs it small (not
a `twinbot bench` benchmark, those: docs/benchmarks.md).  The model:
docs/ir-sensor.md.
"""
from __future__ import annotations

import math
import statistics
import time
from typing import Any

import numpy as np


def _median_time(fn: Any, number: int, repeats: int) -> float:
    """Median over `repeats` of the mean time of `number` calls, in seconds."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return statistics.median(times)


def random_free_poses(world: Any, n: int, rng: np.random.Generator, margin: float = 0.07) -> np.ndarray:
    """n poses (x, y, phi) whose centre is at least `margin` from every wall, inside the area."""
    out = np.empty((0, 3))
    while len(out) < n:
        xy = rng.uniform((0, 0), world.size, size=(2 * n, 2))
        dist, _ = world.nearest_wall(xy)
        xy = xy[dist >= margin]
        out = np.concatenate([out, np.column_stack([xy, rng.uniform(-math.pi, math.pi, len(xy))])])
    return out[:n]


def bench(world: str = "paper_room", repeats: int = 7, batch: int = 1000, power_pct: float = 60.0) -> dict[str, Any]:
    """Medians of `repeats` timed blocks, at random free poses, the noise seeded:

        ray_cast_us        one robot's 8 rays against the room's walls (World.cast_robot), us per call
        read_us            read_sensors for one robot: rays, model, lamp, noise, ADC; us per call
        batch_n            robots in the batch
        batch_ms           read_sensors for batch_n robots, ms per call
        batch_reads_per_s  robot-reads per second in the batch (8 sensors each)
        walls              wall segments in the world
    """
    from host_sim.sensors import ir_sensor
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import world_by_name_or_path

    w = world_by_name_or_path(world)
    rng = np.random.default_rng(1)
    poses = random_free_poses(w, max(batch, 64), rng)
    reach = DEFAULT.sensor_range + DEFAULT.body_radius
    single = [tuple(map(float, q)) for q in poses[:64]]
    arrays = [np.array(q) for q in single]
    k = [0]

    def cast() -> None:
        x, y, phi = single[k[0] & 63]
        k[0] += 1
        w.cast_robot(x, y, phi, ir_sensor.BEARINGS, reach)

    def read() -> None:
        ir_sensor.read_sensors(w, arrays[k[0] & 63], power_pct, 0.04 * k[0], DEFAULT, rng)
        k[0] += 1

    batch_poses = poses[:batch]

    def read_batch() -> None:
        ir_sensor.read_sensors(w, batch_poses, power_pct, 0.0, DEFAULT, rng)

    cast()  # warm the caches
    read()
    read_batch()
    ray = _median_time(cast, 2000, repeats)
    one = _median_time(read, 1000, repeats)
    many = _median_time(read_batch, 5, repeats)
    return {
        "world": w.name,
        "walls": w.n_walls,
        "ray_cast_us": ray * 1e6,
        "read_us": one * 1e6,
        "batch_n": batch,
        "batch_ms": many * 1e3,
        "batch_reads_per_s": batch / many,
    }


if __name__ == "__main__":
    for key, value in bench().items():
        print(f"{key:>18}  {value:.4g}" if isinstance(value, float) else f"{key:>18}  {value}")
