"""Speed of the robot dynamics and motors: one robot's step and a batch of 1000.

`bench(n_steps)` times host_sim/physics/dynamics.py and motors.py, the closed
form against the paper's matrices; `python -m tools.bench.dynamics` prints
it (not a `twinbot bench` benchmark, those: docs/benchmarks.md).  The
equations: docs/dynamics.md.
"""
from __future__ import annotations

import platform
import statistics
import sys
import time
from typing import Any, Callable

DT = 1e-3
N_BATCH = 1000


def _median_time(fn: Callable[[int], None], n: int, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(n)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench(n_steps: int = 20_000) -> dict[str, Any]:
    """Each figure the median of 5 runs of `n_steps` steps (dt = 1 ms, default parameters, a turning robot).

      fast_step_us          one `dynamics.step` (closed form, pure Python)
      fast_step_motors_us   two `motors.wheel_torque` + one `dynamics.step`: one robot's physics per step
      accel_fast_us         one `dynamics.reduced_accel_fast`
      matrix_step_us        one `dynamics.step_matrix` (the paper's matrices rebuilt every step, numpy)
      batch_robot_steps_per_s         `dynamics.step_batch` on N = 1000 robots, each its own parameters
      batch_motors_robot_steps_per_s  the same with `motors.wheel_torque_batch` before each step
    plus the real-time factors of one robot (dt / time per step).
    """
    fast, fast_motors, accel, matrix = _scalar_loops()
    batch, batch_motors = _batch_loops()
    n_matrix = max(1, n_steps // 50)
    n_batch = max(1, n_steps // 50)
    fast_s = _median_time(fast, n_steps) / n_steps
    fast_m_s = _median_time(fast_motors, n_steps) / n_steps
    out: dict[str, Any] = {
        "python": sys.version.split()[0],
        "machine": platform.machine(),
        "dt_s": DT,
        "fast_step_us": fast_s * 1e6,
        "fast_step_motors_us": fast_m_s * 1e6,
        "accel_fast_us": _median_time(accel, n_steps) / n_steps * 1e6,
        "matrix_step_us": _median_time(matrix, n_matrix) / n_matrix * 1e6,
        "batch_n": N_BATCH,
        "batch_robot_steps_per_s": N_BATCH * n_batch / _median_time(batch, n_batch),
        "batch_motors_robot_steps_per_s": N_BATCH * n_batch / _median_time(batch_motors, n_batch),
        "realtime_factor_fast_step": DT / fast_s,
        "realtime_factor_fast_step_motors": DT / fast_m_s,
    }
    out["matrix_over_fast"] = out["matrix_step_us"] / out["fast_step_us"]
    return out


Loop = Callable[[int], None]


def _scalar_loops() -> tuple[Loop, Loop, Loop, Loop]:
    """One robot, n steps: the fast step, with the motors, the acceleration alone, the matrix step."""
    import numpy as np

    from host_sim.physics import dynamics as dy
    from host_sim.physics import motors as mo
    from host_sim.physics.params import DEFAULT as P

    q0: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    v0: tuple[float, float] = (10.0, 14.0)
    tau = (0.004, 0.006)

    def fast(n: int) -> None:
        q, v, step = q0, v0, dy.step
        for _ in range(n):
            q, v = step(q, v, tau, DT, P)

    def fast_motors(n: int) -> None:
        q, v, step, torque = q0, v0, dy.step, mo.wheel_torque
        for _ in range(n):
            t = (torque(0.2, v[0], P)[0], torque(0.3, v[1], P)[0])
            q, v = step(q, v, t, DT, P)

    def accel(n: int) -> None:
        f = dy.reduced_accel_fast
        for _ in range(n):
            f(q0, v0, tau, P)

    def matrix(n: int) -> None:
        qa, va = np.array(q0), np.array(v0)
        for _ in range(n):
            qa, va = dy.step_matrix(qa, va, tau, DT, P)

    return fast, fast_motors, accel, matrix


def _batch_loops() -> tuple[Loop, Loop]:
    """N_BATCH robots of varied mass and centre of mass, n steps: without and with the motors."""
    import numpy as np

    from host_sim.physics import dynamics as dy
    from host_sim.physics import motors as mo
    from host_sim.physics.params import DEFAULT as P

    rng = np.random.default_rng(0)
    pb = dy.ParamBatch.from_params([P.replace(com_offset=float(d), body_mass=float(m))
                                    for d, m in zip(rng.uniform(0, 0.03, N_BATCH), rng.uniform(0.4, 0.5, N_BATCH))])
    qb = np.zeros((N_BATCH, 5))
    vb = rng.uniform(-20, 20, (N_BATCH, 2))
    taub = rng.uniform(-0.01, 0.01, (N_BATCH, 2))
    i_ref = rng.uniform(-0.5, 0.5, (N_BATCH, 2))

    def batch(n: int) -> None:
        q, v = qb.copy(), vb.copy()
        for _ in range(n):
            dy.step_batch(q, v, taub, DT, pb, out=(q, v))

    def batch_motors(n: int) -> None:
        q, v = qb.copy(), vb.copy()
        for _ in range(n):
            t, _i = mo.wheel_torque_batch(i_ref, v, pb)
            dy.step_batch(q, v, t, DT, pb, out=(q, v))

    return batch, batch_motors


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=20_000, help="steps per timed run (default 20000)")
    args = parser.parse_args(argv)
    r = bench(args.steps)
    print(f"python {r['python']} on {r['machine']}, dt = {r['dt_s'] * 1e3:g} ms, median of 5 runs")
    print(f"  fast step (closed form, pure Python)   {r['fast_step_us']:8.2f} us/step   "
          f"({r['realtime_factor_fast_step']:,.0f}x real time)")
    print(f"  fast step + 2 motor torques            {r['fast_step_motors_us']:8.2f} us/step   "
          f"({r['realtime_factor_fast_step_motors']:,.0f}x real time)")
    print(f"  reduced_accel_fast                     {r['accel_fast_us']:8.2f} us/call")
    print(f"  matrix step (paper's matrices, numpy)  {r['matrix_step_us']:8.2f} us/step   "
          f"({r['matrix_over_fast']:.0f}x the fast step)")
    print(f"  step_batch, N = {r['batch_n']}                  {r['batch_robot_steps_per_s']:12,.0f} robot-steps/s")
    print(f"  step_batch + motors, N = {r['batch_n']}         {r['batch_motors_robot_steps_per_s']:12,.0f} robot-steps/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
