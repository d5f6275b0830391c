"""`twinbot bench sim`: how fast the host simulator runs, with IR-SIM beside it.

One robot replaying a recording, one with the firmware in SIL, a batch of
robots with their own parameters, and IR-SIM on the same room; DESCRIPTION
(the --help text) says what each workload times.  Figures: docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import io
import json
import math
import os
import platform
import pstats
import statistics
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from typing import Any, Callable

from tools.bench.report import print_targets

DESCRIPTION = """\
Measured in one run, each figure the median of --repeats timed runs, all in
the paper's room (host_sim/worlds/paper_room.json), fixed step, as fast as
possible, nothing drawn:
  (a) replay: one robot replaying a recording's inputs open loop
      (host_sim.recordings.replay.replay: physics + motors + encoders + IR sensors with
      noise + contacts, 8 substeps per 40 ms).  The recording is made first
      by a SIL run of --seconds simulated seconds (refined rules).
  (b) SIL: one robot with the firmware in the loop (Simulation + SilController,
      Simulation.run_fixed, speed max); and the same with each IR sensor a
      beam of BEAM_RAYS rays (ir_beam_rays, docs/ir-sensor.md) instead of
      one ray: the beam's cost.
  (c) batch: host_sim.robot.batch.BatchSim, N robots (--batch-n, 1000) with N
      different parameter sets (mass, wheel radius, half axle, motor constant,
      frictions within +-10 %), replaying the recording's first
      --batch-seconds from its first row: the core loop of identification;
      with and without the IR sensors.
  (d) IR-SIM (PyPI ir-sim), headless: one differential-drive robot (circle,
      the same body radius), lidar2d with 8 beams every 45 degrees (the IR
      ring's bearings, reaching as far as the IR model), every wall of the
      room as a linestring or polygon obstacle, step_time 40 ms (the scene is
      written as an IR-SIM YAML world file in a temporary folder); env.step()
      driven with the recording's forward speed and yaw rate (from its
      encoder counts), so it takes roughly the same path.  Its counterpart
      among ours is (a): one robot and a ring of 8 range readings per 40 ms.

A robot-step is one robot advanced by one physics step (dt = 40 ms / 8 =
5 ms: motor model at mid-step, dynamics, grip and wall tests, and the contact
step where a wheel slips or a wall is hit).  A robot-period is one robot
advanced by one 40 ms control period: 8 robot-steps plus the readings at the
control instant (encoders, and the IR ring when sensors are on).  IR-SIM has
no substeps: one env.step() is one robot-period and one robot-step.
"""

TARGET_REPLAY_RTF = 1000.0
TARGET_SIL_RTF = 200.0
TARGET_BATCH_STEPS = 1_000_000.0
TARGET_BATCH_N = 1000
WORLD = "paper_room"
CYCLE_S = 0.040
SUBSTEPS = 8
PERTURBED = ("body_mass", "wheel_radius", "half_axle", "torque_constant", "viscous_friction", "coulomb_friction")

ROW_REPLAY = "(a) replay, 1 robot, physics + motors + IR"
ROW_SIL = "(b) SIL firmware, 1 robot"
ROW_SIL_BEAM = "(b) SIL firmware, 1 robot, IR beam of {rays} rays"
BEAM_RAYS = 5
ROW_BATCH = "(c) batch, N={n} parameter sets, no IR"
ROW_BATCH_IR = "(c) batch, N={n} parameter sets, with IR"
ROW_IRSIM = "(d) IR-SIM {version}, 1 robot + 8-beam lidar"


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    from tools.arguments import float_range, int_range, output_file

    p.add_argument("--seconds", type=float_range(0.2, 3600, unit="s"), default=30.0,
                   help="simulated seconds of the single-robot workloads (a), (b), (d) (default 30)")
    p.add_argument("--batch-n", type=int_range(1, 1_000_000), default=TARGET_BATCH_N,
                   help="robots in the batch (default 1000)")
    p.add_argument("--batch-seconds", type=float_range(0.04, 3600, unit="s"), default=2.0,
                   help="simulated seconds of each batch run (default 2, i.e. 50 control periods)")
    p.add_argument("--repeats", type=int_range(1, 1000), default=5,
                   help="timed runs per workload; the median is kept (default 5)")
    p.add_argument("--profile", action="store_true",
                   help="profile (cProfile) every workload of ours, not only those that miss their target")
    p.add_argument("--json", metavar="FILE", type=output_file, help="write every figure here")
    p.set_defaults(func=run)


def pin_blas_threads() -> str:
    """One BLAS thread, unless the user chose (OPENBLAS_NUM_THREADS) or numpy is already loaded.

    Every workload here is single-threaded Python; the only BLAS call is the
    small matrix product of World.cast_robots, where OpenBLAS's thread pool
    only adds hand-offs (and, on a busy machine, spinning threads: 2-4x slower
    batches with IR on a loaded 2-CPU machine).  Must run before numpy is imported.
    """
    chosen = os.environ.get("OPENBLAS_NUM_THREADS")
    if chosen:
        return f"{chosen} (OPENBLAS_NUM_THREADS)"
    if "numpy" in sys.modules:
        return "OpenBLAS default (numpy was loaded before the benchmark started)"
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return "1 (set by the benchmark; OPENBLAS_NUM_THREADS=N to choose)"


def _progress(text: str) -> None:
    print(f"  ... {text}", file=sys.stderr, flush=True)


def _median_time(fn: Callable[[], object], repeats: int) -> tuple[float, list[float]]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times


# --------------------------------------------------------------------------- #
# Profiling: where the time of one workload goes
# --------------------------------------------------------------------------- #
# (label, file, function): the parts each profiled workload is split into (cumulative time).
COMPONENTS = {
    "(a) replay": [
        ("IR sensors + encoders (SimRobot.sense)", "host_sim/robot/sim_robot.py", "sense"),
        ("8 physics steps (SimRobot.advance)", "host_sim/robot/sim_robot.py", "advance"),
        ("  of which the wall test (BatchSim._walls_near_one)", "host_sim/robot/batch.py", "_walls_near_one"),
        ("  of which motors + dynamics (drivetrain.drive_step)", "host_sim/physics/drivetrain.py", "drive_step"),
        ("  of which the grip test (contact.traction_ok)", "host_sim/physics/contact.py", "traction_ok"),
        ("  of which contact steps (contact.slip_step)", "host_sim/physics/contact.py", "slip_step"),
    ],
    "(b) SIL": [
        ("IR sensors + encoders (SimRobot.sense)", "host_sim/robot/sim_robot.py", "sense"),
        ("8 physics steps (SimRobot.advance)", "host_sim/robot/sim_robot.py", "advance"),
        ("firmware cycle (SilController.cycle)", "host_sim/controller/sil.py", "cycle"),
        ("coverage bookkeeping (Coverage.add)", "host_sim/loops/coverage.py", "add"),
    ],
    "(c) batch with IR": [
        ("IR sensors (read_sensors)", "host_sim/sensors/ir_sensor.py", "read_sensors"),
        ("  of which the ray cast (World.cast_robots)", "host_sim/physics/world.py", "cast_robots"),
        ("motors (wheel_torque_batch)", "host_sim/physics/motors.py", "wheel_torque_batch"),
        ("dynamics (step_batch)", "host_sim/physics/dynamics.py", "step_batch"),
        ("grip tests (contact.traction_ok_batch)", "host_sim/physics/contact.py", "traction_ok_batch"),
        ("wall tests (BatchSim._walls_in_reach)", "host_sim/robot/batch.py", "_walls_in_reach"),
        ("contact steps (contact.slip_step_batch)", "host_sim/physics/contact.py", "slip_step_batch"),
        ("encoders (encoder_ticks_batch)", "host_sim/physics/motors.py", "encoder_ticks_batch"),
    ],
}


def profile(fn: Callable[[], object], components: list[tuple[str, str, str]] = (),  # type: ignore[assignment]
            top: int = 10) -> dict[str, Any]:
    """cProfile one call: cumulative time of the named components, the functions with the
    most own time, and own time by file.  (The profiler slows Python code more than C code:
    shares are indicative.)"""
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    fn()
    prof.disable()
    wall = time.perf_counter() - t0
    st = pstats.Stats(prof)
    stats = st.stats  # type: ignore[attr-defined]
    total = sum(v[2] for v in stats.values()) or 1e-12
    rows: list[dict[str, Any]] = []
    by_file: dict[str, float] = {}
    for (file, line, func), (_cc, ncalls, tottime, cumtime, _callers) in stats.items():
        where = _short(file)
        label = f"{where}:{line}({func})" if line else f"{func}"
        rows.append({"function": label, "calls": ncalls, "own_s": tottime, "cum_s": cumtime,
                     "own_share": tottime / total})
        key = where if line else "built-ins and numpy C code"
        by_file[key] = by_file.get(key, 0.0) + tottime
    rows.sort(key=lambda r: -r["own_s"])
    files = [{"file": k, "own_s": v, "own_share": v / total}
             for k, v in sorted(by_file.items(), key=lambda kv: -kv[1])]
    parts = []
    for label, file, func in components:
        cum = sum(v[3] for (f, _line, fn_name), v in stats.items()
                  if fn_name == func and _short(f) == file)
        calls = sum(v[1] for (f, _line, fn_name), v in stats.items() if fn_name == func and _short(f) == file)
        parts.append({"part": label, "cum_s": cum, "share": cum / total, "calls": calls})
    return {"total_s": total, "wall_s": wall, "components": parts, "top": rows[:top], "by_file": files[:8]}


_ROOT = str(Path(__file__).resolve().parents[2]) + os.sep


def _short(file: str) -> str:
    if file.startswith(_ROOT):
        return file[len(_ROOT):]
    if "site-packages" + os.sep in file:
        return file.split("site-packages" + os.sep, 1)[1]
    return file


def format_profile(name: str, prof: dict[str, Any]) -> str:
    lines = [f"where the time goes, {name} (cProfile, one run, {prof['total_s']:.2f} s under the profiler):"]
    for part in prof["components"]:
        lines.append(f"  {100 * part['share']:5.1f} %  {part['part']}  ({part['calls']} calls)")
    lines.append("  own time by file: " + ", ".join(f"{r['file']} {100 * r['own_share']:.0f} %"
                                                     for r in prof["by_file"][:6]))
    lines.append("  functions by own time:")
    for r in prof["top"]:
        lines.append(f"    {100 * r['own_share']:5.1f} %  {r['calls']:>8} calls  cum {r['cum_s']:6.3f} s  "
                     f"{r['function']}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- #
# The workloads
# --------------------------------------------------------------------------- #
def make_recording(path: Path, seconds: float) -> Any:
    """A SIL run in the paper's room, recorded (the input of (a), (c) and (d))."""
    from host_sim.controller.sil import SilController
    from host_sim.physics.params import DEFAULT
    from host_sim.recordings.recording import RecordingWriter, load_recording
    from host_sim.loops.simulation import Simulation
    from host_sim.physics.world import builtin_world

    world = builtin_world(WORLD)
    with RecordingWriter(path, source="simulator", sample_period=CYCLE_S, robot=DEFAULT.to_json(),
                         world=world.to_dict(), extra={"controller": "SIL", "rules": "refined", "seed": 0,
                                                       "mode": "fixed", "substeps": SUBSTEPS, "noise": True,
                                                       "emitter_pct": 60}) as rec:
        Simulation(world, DEFAULT, SilController(1), seed=0, recorder=rec, substeps=SUBSTEPS).run_fixed(seconds)
    return load_recording(path)


def bench_replay(rec: Any, repeats: int) -> dict[str, Any]:
    import numpy as np

    from host_sim.physics.params import DEFAULT
    from host_sim.recordings.replay import replay
    from host_sim.physics.world import builtin_world

    world = builtin_world(WORLD)
    out: dict[str, Any] = {}

    def once() -> None:
        out["result"] = replay(rec, DEFAULT, world, seed=0)

    wall, times = _median_time(once, repeats)
    sim_s = len(rec) * CYCLE_S
    res = out["result"]
    return {"sim_s": sim_s, "wall_s": wall, "times_s": times, "rtf": sim_s / wall, "periods": len(rec),
            "robot_steps_per_s": len(rec) * SUBSTEPS / wall, "robot_periods_per_s": len(rec) / wall,
            "reproduces_recording": bool(np.array_equal(res.pose, rec.pose) and np.array_equal(res.enc, rec.enc))}


def bench_sil(seconds: float, repeats: int, beam_rays: int = 1) -> dict[str, Any]:
    from host_sim.controller.sil import SilController
    from host_sim.physics.params import DEFAULT
    from host_sim.loops.simulation import Simulation
    from host_sim.physics.world import builtin_world

    world = builtin_world(WORLD)
    params = DEFAULT.replace(ir_beam_rays=beam_rays)
    times = []
    result = None
    for _ in range(repeats):
        sim = Simulation(world, params, SilController(1), seed=0, substeps=SUBSTEPS)
        t0 = time.perf_counter()
        result = sim.run_fixed(seconds)
        times.append(time.perf_counter() - t0)
    assert result is not None
    wall = statistics.median(times)
    periods = len(result.t)
    return {"sim_s": result.sim_seconds, "wall_s": wall, "times_s": times, "rtf": result.sim_seconds / wall,
            "periods": periods, "robot_steps_per_s": result.steps / wall, "robot_periods_per_s": periods / wall,
            "collisions": result.collisions, "coverage": float(result.coverage[-1]), "beam_rays": beam_rays}


def batch_params(n: int, seed: int = 0) -> Any:
    """N parameter sets: the defaults with PERTURBED scaled by U(0.9, 1.1) (the first one unperturbed)."""
    import numpy as np

    from host_sim.physics.dynamics import ParamBatch
    from host_sim.physics.params import DEFAULT

    rng = np.random.default_rng(seed)
    scale = rng.uniform(0.9, 1.1, (n, len(PERTURBED)))
    scale[0] = 1.0
    return ParamBatch.from_vectors(np.array(DEFAULT.to_vector(list(PERTURBED))) * scale, list(PERTURBED))


def bench_batch(rec: Any, n: int, seconds: float, sensors: bool, repeats: int) -> dict[str, Any]:
    import numpy as np

    from host_sim.robot.batch import BatchSim
    from host_sim.physics.world import builtin_world

    world = builtin_world(WORLD)
    params = batch_params(n)
    periods = max(1, min(len(rec), int(round(seconds / CYCLE_S))))
    cmd = rec.cmd[:periods]
    start = np.tile(rec.pose[0], (n, 1))
    times = []
    collisions = 0
    spread = 0.0
    for _ in range(repeats):
        # As host_sim.recordings.replay.replay_batch from row 0 of a simulator recording:
        # every robot at rest at the recorded start, emitters off until the first command.
        sim = BatchSim(world, params, start, initial_emitter_pct=0, substeps=SUBSTEPS, cycle_s=CYCLE_S)
        t0 = time.perf_counter()
        res = sim.run_inputs(cmd, sensors=sensors, seed=0 if sensors else None)
        times.append(time.perf_counter() - t0)
        collisions = int(res.collisions.sum())
        end = res.pose[-1, :, :2]
        spread = float(np.hypot(*(end - end[0]).T).max())
    wall = statistics.median(times)
    return {"n": n, "sensors": sensors, "periods": periods, "sim_s_per_robot": periods * CYCLE_S,
            "wall_s": wall, "times_s": times, "robot_steps_per_s": n * periods * SUBSTEPS / wall,
            "robot_periods_per_s": n * periods / wall, "rtf_per_robot": periods * CYCLE_S / wall,
            "collisions": collisions, "max_end_distance_from_nominal_m": spread}


# --------------------------------------------------------------------------- #
# IR-SIM
# --------------------------------------------------------------------------- #
def _import_irsim() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # before IR-SIM picks a backend; nothing is drawn anyway (headless)
    # IR-SIM tries the interactive backends at import and prints each failure.
    with contextlib.redirect_stdout(io.StringIO()):
        import irsim  # type: ignore[import-untyped]
    return irsim


def irsim_yaml(world: Any, params: Any, step_s: float) -> str:
    """The room as an IR-SIM world file (YAML): robot, 8-beam lidar, every wall."""
    import yaml  # type: ignore[import-untyped]  # PyYAML: IR-SIM reads its world files with it
    reach = params.sensor_range + params.body_radius  # ours: rays from the centre, this far
    # lidar2d spreads `number` beams over angle_range with both ends included:
    # 8 beams over 315 degrees, turned by 22.5 degrees, are the ring's 0, 45, ..., 315.
    n = 8
    span = 2 * math.pi * (n - 1) / n
    obstacles = []
    for wall in world.walls:
        if "segment" in wall:
            x1, y1, x2, y2 = wall["segment"]
            shape = {"name": "linestring", "vertices": [[x1, y1], [x2, y2]]}
        else:
            shape = {"name": "polygon", "vertices": [list(map(float, p)) for p in wall["polygon"]]}
        # Vertices are in the obstacle's frame: put that frame at the origin.
        obstacles.append({"shape": shape, "state": [0.0, 0.0, 0.0], "static": True})
    x, y, phi = world.start
    scene = {
        "world": {"width": world.size[0], "height": world.size[1], "step_time": step_s,
                  "sample_time": step_s, "collision_mode": "stop", "control_mode": "auto"},
        "robot": [{
            "kinematics": {"name": "diff"},
            "shape": {"name": "circle", "radius": params.body_radius},
            "state": [x, y, phi],
            "vel_min": [-2.0, -30.0], "vel_max": [2.0, 30.0],
            "sensors": [{"name": "lidar2d", "range_min": 0.0, "range_max": reach, "angle_range": span,
                         "number": n, "offset": [0.0, 0.0, math.pi / n], "noise": False}],
        }],
        "obstacle": obstacles,
    }
    return yaml.safe_dump(scene, sort_keys=False, default_flow_style=None)


def recording_velocities(rec: Any, params: Any) -> Any:
    """(T, 2) forward speed (m/s) and yaw rate (rad/s) of each row, from the encoder counts."""
    import numpy as np

    per_tick = 2 * math.pi / params.ticks_per_rev
    w = np.diff(rec.enc, axis=0, append=rec.enc[-1:]) * per_tick / CYCLE_S
    r, b = params.wheel_radius, params.half_axle
    return np.column_stack([0.5 * r * (w[:, 0] + w[:, 1]), 0.5 * r * (w[:, 1] - w[:, 0]) / b])


def bench_irsim(rec: Any, seconds: float, repeats: int, tmp: Path) -> dict[str, Any]:
    import numpy as np

    from host_sim.sensors import ir_sensor
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import builtin_world

    irsim = _import_irsim()
    world = builtin_world(WORLD)
    path = tmp / "irsim_paper_room.yaml"
    path.write_text(irsim_yaml(world, DEFAULT, CYCLE_S))
    actions = recording_velocities(rec, DEFAULT)
    # After k steps IR-SIM's robot should be near ours at row k (recorded before row k's command).
    steps = max(1, min(len(rec) - 1, int(round(seconds / CYCLE_S))))
    acts = [np.array([[v], [w]]) for v, w in actions[:steps]]

    def make_env() -> Any:
        with contextlib.redirect_stdout(io.StringIO()):
            return irsim.make(str(path), headless=True, log_level="ERROR", seed=0)

    # The scene check (untimed): along IR-SIM's whole run, its 8 ranges against
    # our ray cast from the same poses, so both hold the same walls.
    env = make_env()
    sensor = env.robot.sensors[0]
    order = np.argsort(np.mod(np.round(sensor.angle_list + math.pi / 8, 9), 2 * math.pi))
    states, scans = [], []
    for a in [None] + acts:
        if a is not None:
            env.step(a)
        states.append(np.asarray(env.robot.state, dtype=float).ravel()[:3])
        scans.append(np.asarray(sensor.get_scan()["ranges"], dtype=float)[order])
    with contextlib.redirect_stdout(io.StringIO()):
        env.end(0)
    reach = DEFAULT.sensor_range + DEFAULT.body_radius
    ours, _inc, _hit = world.cast_robots(np.array(states), ir_sensor.BEARINGS, reach)
    scene_error = float(np.abs(np.array(scans) - np.minimum(ours, reach)).max())

    times = []
    end_pose = None
    for _ in range(repeats):
        env = make_env()
        t0 = time.perf_counter()
        for a in acts:
            env.step(a)
        times.append(time.perf_counter() - t0)
        end_pose = np.asarray(env.robot.state, dtype=float).ravel()[:3]
        with contextlib.redirect_stdout(io.StringIO()):
            env.end(0)
    wall = statistics.median(times)
    assert end_pose is not None
    ours_end = rec.pose[steps]
    return {"version": irsim.__version__, "steps": steps, "sim_s": steps * CYCLE_S, "wall_s": wall,
            "times_s": times, "rtf": steps * CYCLE_S / wall, "robot_steps_per_s": steps / wall,
            "robot_periods_per_s": steps / wall, "scene_check_max_range_error_m": scene_error,
            "scene_check_scans": len(scans),
            "end_pose": end_pose.tolist(), "end_distance_from_ours_m": float(np.hypot(*(end_pose[:2] - ours_end[:2]))),
            "yaml": path.read_text()}


# --------------------------------------------------------------------------- #
# Report
# --------------------------------------------------------------------------- #
def _num(x: float, digits: int = 0) -> str:
    return f"{x:,.{digits}f}"


def _secs(x: float) -> str:
    return f"{x:.3f}" if x < 10 else f"{x:.2f}"


def format_table(report: dict[str, Any]) -> str:
    r = report["results"]
    n = report["batch_n"]
    rows: list[tuple[str, ...]] = []
    a, b, d = r["replay"], r["sil"], r["irsim"]
    rows.append((ROW_REPLAY, _num(a["sim_s"], 1), _secs(a["wall_s"]), _num(a["rtf"]) + "x",
                 _num(a["robot_periods_per_s"]), _num(a["robot_steps_per_s"])))
    rows.append((ROW_SIL, _num(b["sim_s"], 1), _secs(b["wall_s"]), _num(b["rtf"]) + "x",
                 _num(b["robot_periods_per_s"]), _num(b["robot_steps_per_s"])))
    bb = r["sil_beam"]
    rows.append((ROW_SIL_BEAM.format(rays=bb["beam_rays"]), _num(bb["sim_s"], 1), _secs(bb["wall_s"]),
                 _num(bb["rtf"]) + "x", _num(bb["robot_periods_per_s"]), _num(bb["robot_steps_per_s"])))
    for key, label in (("batch", ROW_BATCH), ("batch_ir", ROW_BATCH_IR)):
        c = r[key]
        rows.append((label.format(n=n), f"{_num(c['sim_s_per_robot'], 1)} x {n}", _secs(c["wall_s"]),
                     _num(c["rtf_per_robot"]) + "x each", _num(c["robot_periods_per_s"]),
                     _num(c["robot_steps_per_s"])))
    if "error" in d:
        rows.append((ROW_IRSIM.format(version="?"), "not run", "-", "-", "-", "-"))
    else:
        rows.append((ROW_IRSIM.format(version=d["version"]), _num(d["sim_s"], 1), _secs(d["wall_s"]),
                     _num(d["rtf"]) + "x", _num(d["robot_periods_per_s"]), _num(d["robot_steps_per_s"])))
    header = ("workload", "sim s", "wall s", "real-time factor", "robot-periods/s", "robot-steps/s")
    widths = [max(len(row[i]) for row in rows + [header]) for i in range(len(header))]

    def line(cells: tuple[str, ...]) -> str:
        return " | ".join([cells[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(cells[1:], widths[1:])])

    return "\n".join([line(header), "-+-".join("-" * w for w in widths)] + [line(row) for row in rows])


def targets(report: dict[str, Any]) -> list[dict[str, Any]]:
    r = report["results"]
    n = report["batch_n"]
    out = [
        {"name": "replay_rtf", "met": r["replay"]["rtf"] >= TARGET_REPLAY_RTF,
         "text": f"one robot replaying inputs, fixed step, >= {TARGET_REPLAY_RTF:,.0f}x real time: "
                 f"{r['replay']['rtf']:,.0f}x"},
        {"name": "sil_rtf", "met": r["sil"]["rtf"] >= TARGET_SIL_RTF,
         "text": f"one robot with the firmware in SIL, >= {TARGET_SIL_RTF:,.0f}x real time: {r['sil']['rtf']:,.0f}x"},
    ]
    for key, what in (("batch", "without IR"), ("batch_ir", "with IR")):
        c = r[key]
        full = n >= TARGET_BATCH_N
        out.append({"name": f"{key}_robot_steps", "met": c["robot_steps_per_s"] >= TARGET_BATCH_STEPS and full,
                    "text": f"batch >= {TARGET_BATCH_STEPS:,.0f} robot-steps/s at N = {TARGET_BATCH_N}, {what}: "
                            f"{c['robot_steps_per_s']:,.0f} at N = {n}"
                            + ("" if full else " (N too small to count)")})
        out.append({"name": f"{key}_robot_periods", "met": c["robot_periods_per_s"] >= TARGET_BATCH_STEPS and full,
                    "text": f"  the same, counting a whole 40 ms period as the step, {what}: "
                            f"{c['robot_periods_per_s']:,.0f} robot-periods/s"})
    d = r["irsim"]
    if "error" in d:
        out.append({"name": "faster_than_irsim", "met": None, "text": f"faster than IR-SIM: not run ({d['error']})"})
    else:
        ratio = r["replay"]["rtf"] / d["rtf"]
        report["ratio_replay_vs_irsim"] = ratio
        out.append({"name": "faster_than_irsim", "met": ratio > 1.0,
                    "text": f"faster than IR-SIM on the comparable scene: (a) / (d) = {ratio:.2f} "
                            f"({r['replay']['rtf']:,.0f}x vs {d['rtf']:,.0f}x real time)"})
    return out


def print_report(report: dict[str, Any]) -> None:
    from host_sim.physics.params import DEFAULT

    m = report["machine"]
    r = report["results"]
    print("twinbot bench sim")
    print(f"command:     {report['command']}")
    print(f"machine:     {m['platform']}, {m['processor']}, {m['cpus']} CPUs, load average {m['load']}")
    print(f"python:      CPython {m['python']}, numpy {m['numpy']}, BLAS threads {m['blas_threads']}")
    print(f"world:       {WORLD}, fixed step, 40 ms control period, {SUBSTEPS} physics steps per period; "
          f"median of {report['repeats']} run{'s' if report['repeats'] != 1 else ''}")
    print()
    print(format_table(report))
    print()
    def note(label: str, text: str) -> None:
        print(textwrap.fill(text, 108, initial_indent=f"{label:<14}", subsequent_indent=" " * 14))

    note("robot-step:", "one robot advanced by one physics step of 5 ms (40 ms / 8): motor model, dynamics, "
                        "grip and wall tests, contact step where needed.  robot-period: one robot advanced by one 40 ms control period = 8 "
                        "robot-steps + the readings at the control instant (encoders; IR ring if on).  IR-SIM "
                        "has no substeps: one env.step() of 40 ms counts as one of each.")
    d = r["irsim"]
    note("(a):", f"replays the {r['replay']['sim_s']:.0f} s SIL recording (sensor noise on); reproduces the "
                 f"recording's pose and encoders bit for bit: {'yes' if r['replay']['reproduces_recording'] else 'NO'}")
    b, bb = r["sil"], r["sil_beam"]
    note("(b) beam:", f"each IR sensor {bb['beam_rays']} rays over +-{DEFAULT.ir_beam_half_angle:.2f} rad instead "
                      f"of one: {b['rtf'] / bb['rtf']:.2f} times the wall time of (b)")
    c = r["batch_ir"]
    note("(c):", f"{report['batch_n']} parameter sets ({', '.join(PERTURBED)} x U(0.9, 1.1)) replay the first "
                 f"{c['sim_s_per_robot']:.1f} s of that recording; spread of the end positions "
                 f"{100 * c['max_end_distance_from_nominal_m']:.1f} cm, {c['collisions']} contacts")
    if "error" in d:
        note("(d):", f"IR-SIM not run: {d['error']}")
    else:
        note("(d):", f"the same walls ({report['walls']} segments and polygons), driven with the recording's "
                     f"speeds; along its run IR-SIM's 8 ranges equal our ray cast from its poses to "
                     f"{d['scene_check_max_range_error_m']:.1e} m; its robot ends "
                     f"{1000 * d['end_distance_from_ours_m']:.1f} mm from ours (kinematic, open loop).  (a) is "
                     f"the comparable workload: one robot + a ring of 8 ranges every 40 ms (ours also runs the "
                     f"dynamics 8 times per period and the IR response model).")
    print_targets(report["targets"])
    for name, prof in report.get("profiles", {}).items():
        print()
        print(format_profile(name, prof))
    print(f"\nelapsed: {report['elapsed_s']:.1f} s")


def run(args: argparse.Namespace) -> int:
    blas = pin_blas_threads()
    from host_sim.physics.world import builtin_world

    t_start = time.monotonic()
    command = (f"twinbot bench sim --seconds {args.seconds:g} --batch-n {args.batch_n} "
               f"--batch-seconds {args.batch_seconds:g} --repeats {args.repeats}"
               + (" --profile" if args.profile else ""))
    with tempfile.TemporaryDirectory(prefix="twinbot-bench-sim-") as tmp_name:
        tmp = Path(tmp_name)
        _progress(f"recording a {args.seconds:g} s SIL run in {WORLD}")
        rec = make_recording(tmp / "sil.csv", args.seconds)
        results = _bench_all(args, rec, tmp)
        report: dict[str, Any] = {
            "command": command, "repeats": args.repeats, "batch_n": args.batch_n,
            "walls": len(builtin_world(WORLD).walls), "robot_step": "one robot advanced by one 5 ms physics step",
            "robot_period": "one robot advanced by one 40 ms control period (8 robot-steps + readings)",
            "machine": _machine(blas),  # after the runs: the load average they saw
            "results": results,
        }
        report["targets"] = targets(report)
        missed = {t["name"] for t in report["targets"] if t["met"] is False}
        report["profiles"] = _profiles(args, rec, missed)
    report["elapsed_s"] = time.monotonic() - t_start
    print_report(report)
    if args.json:
        from tools.arguments import writing

        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(report, indent=2, default=str))
    return 0


def _bench_all(args: argparse.Namespace, rec: Any, tmp: Path) -> dict[str, Any]:
    """(a) to (d) on the recording, in that order."""
    results: dict[str, Any] = {}
    _progress("(a) replay of the recording, one robot")
    results["replay"] = bench_replay(rec, args.repeats)
    _progress("(b) SIL, one robot")
    results["sil"] = bench_sil(args.seconds, args.repeats)
    _progress(f"(b) SIL, one robot, IR beam of {BEAM_RAYS} rays")
    results["sil_beam"] = bench_sil(args.seconds, args.repeats, BEAM_RAYS)
    _progress(f"(c) batch, N = {args.batch_n}, without and with IR")
    results["batch"] = bench_batch(rec, args.batch_n, args.batch_seconds, False, args.repeats)
    results["batch_ir"] = bench_batch(rec, args.batch_n, args.batch_seconds, True, args.repeats)
    _progress("(d) IR-SIM on the same room")
    try:
        results["irsim"] = bench_irsim(rec, args.seconds, args.repeats, tmp)
    except ImportError as exc:
        results["irsim"] = {"error": f"ir-sim is not installed ({exc}); pip install ir-sim"}
    return results


def _machine(blas: str) -> dict[str, Any]:
    import numpy as np

    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "blas_threads": blas,
            "load": " ".join(f"{x:.2f}" for x in os.getloadavg())}


def _profiles(args: argparse.Namespace, rec: Any, missed: set[str]) -> dict[str, Any]:
    """Where the time goes, for each part that missed its target (all of them with --profile)."""
    profiles: dict[str, Any] = {}
    if not (args.profile or missed):
        return profiles
    from host_sim.physics.params import DEFAULT
    from host_sim.recordings.replay import replay
    from host_sim.controller.sil import SilController
    from host_sim.loops.simulation import Simulation
    from host_sim.physics.world import builtin_world

    world = builtin_world(WORLD)
    if args.profile or "replay_rtf" in missed:
        _progress("profiling (a)")
        profiles["(a) replay"] = profile(lambda: replay(rec, DEFAULT, world, seed=0), COMPONENTS["(a) replay"])
    if args.profile or "sil_rtf" in missed:
        _progress("profiling (b)")
        profiles["(b) SIL"] = profile(
            lambda: Simulation(world, DEFAULT, SilController(1), seed=0).run_fixed(args.seconds),
            COMPONENTS["(b) SIL"])
    if args.profile or missed & {"batch_robot_steps", "batch_ir_robot_steps"}:
        _progress("profiling (c)")
        profiles["(c) batch with IR"] = profile(
            lambda: bench_batch(rec, args.batch_n, args.batch_seconds, True, 1), COMPONENTS["(c) batch with IR"])
    return profiles
