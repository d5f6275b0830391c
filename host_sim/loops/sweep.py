"""Many fixed-step exploration runs, on local cores or a Dask cluster (docs/sweep.md).

A case is one fixed-step SIL run, a pure function of its fields, so a row does not depend
on where it ran.  Its seed draws the sensor noise, a start near the world's (`draw_start`)
and the perturbed robot parameters (`draw_params`; the plant's only: the firmware keeps the
nominal geometry).  `run_cases` runs the cases on Dask distributed; `write_table`,
`summarise` and `save_coverage_plot` write the results.
"""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import logging
import math
import os
import signal
import threading
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

STUCK_WINDOW_S = 20.0  # "stuck": in the last 20 s of the run ...
STUCK_DISTANCE_M = 0.05  # ... the centre never got 5 cm from where it was 20 s before the end
CURVE_PERIOD_S = 1.0  # coverage curve kept for the plots: one sample a second

START_RADIUS_M = 0.05  # default start jitter: the centre anywhere within 5 cm of the world's start ...
START_HEADING_DEG = 15.0  # ... and the heading within +-15 degrees of it
START_TRIES = 100  # draws of a start clear of the walls before the world's own start is taken
START_CLEARANCE_M = 0.005  # a drawn start keeps the body this far from every wall (no contact at t = 0)

COLUMNS = ("rules", "world", "seed", "duration_s", "start_x_m", "start_y_m", "start_phi_rad", "coverage_end",
           "t90_s", "exit_found", "exit_time_s", "collisions", "stuck", "moved_last_window_m")


@dataclass(frozen=True)
class Case:
    rules: str
    world: str
    seed: int
    duration: float
    substeps: int = 8
    start_radius: float = 0.0  # m
    start_heading_deg: float = 0.0
    perturb: tuple[tuple[str, float], ...] = ()  # (RobotParams field, relative half-range)


def columns(perturb: Sequence[tuple[str, float]] = ()) -> tuple[str, ...]:
    """The table's columns: COLUMNS, then the value each run drew for each perturbed parameter."""
    return COLUMNS + tuple(name for name, _rel in perturb)


def check_perturb(name: str, rel: float) -> None:
    """ValueError (one line) unless NAME is a RobotParams number a relative perturbation moves, 0 <= REL < 1."""
    from host_sim.physics.params import DEFAULT, INTEGER_PARAMS

    fields = {f.name for f in dataclasses.fields(DEFAULT)}
    if name not in fields:
        import difflib

        close = difflib.get_close_matches(name, sorted(fields), n=1, cutoff=0.75)
        raise ValueError(f"unknown parameter '{name}'" + (f" (did you mean {close[0]}?)" if close else "")
                         + ": the names are RobotParams' fields (host_sim/physics/params.py)")
    nominal = getattr(DEFAULT, name)
    if isinstance(nominal, tuple) or name in INTEGER_PARAMS:
        raise ValueError(f"'{name}' is {'a list' if isinstance(nominal, tuple) else 'a whole number'}: "
                         f"perturb a scalar real parameter")
    if nominal == 0:
        raise ValueError(f"'{name}' is 0 by default: a relative perturbation leaves it 0")
    if not (math.isfinite(rel) and 0.0 <= rel < 1.0):
        raise ValueError(f"'{name}={rel:g}': REL must be a fraction in [0, 1), e.g. 0.02 for +-2 %")
    from host_sim.physics.params import ParamsError, params_from_dict

    for end in (nominal * (1 - rel), nominal * (1 + rel)):  # the checks are ranges: both ends must pass
        try:
            params_from_dict({name: end}, f"'{name}={rel:g}'")
        except ParamsError as exc:
            raise ValueError(f"{exc} at the end of its range") from None


def _stream(seed: int, purpose: str):  # type: ignore[no-untyped-def]
    """A generator of the seed's own for one purpose: independent of the sensor noise and of the others."""
    return np.random.default_rng([seed, zlib.crc32(purpose.encode())])


def draw_start(case: Case, world, body_radius: float) -> tuple[float, float, float]:  # type: ignore[no-untyped-def]
    """The run's start: uniform in the disc of start_radius about the world's start, clear of every wall."""
    x0, y0, phi0 = world.start
    if case.start_radius <= 0 and case.start_heading_deg <= 0:
        return world.start
    rng = _stream(case.seed, "start")
    for _ in range(START_TRIES):
        r, a = case.start_radius * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
        dphi = math.radians(case.start_heading_deg) * rng.uniform(-1, 1)
        x, y = x0 + r * math.cos(a), y0 + r * math.sin(a)
        point = np.array([x, y])
        clear = not world.n_walls or float(world.nearest_wall(point)[0]) >= body_radius + START_CLEARANCE_M  # type: ignore[index]
        if clear and not world.outside(point):
            return x, y, phi0 + dphi
    return world.start


def draw_params(case: Case):  # type: ignore[no-untyped-def]
    """The plant's RobotParams: each perturbed field uniform within +-REL of nominal, a stream per name."""
    from host_sim.physics.params import DEFAULT

    changes = {}
    for name, rel in case.perturb:
        nominal = float(getattr(DEFAULT, name))
        changes[name] = nominal * (1.0 + rel * _stream(case.seed, f"param:{name}").uniform(-1, 1))
    return dataclasses.replace(DEFAULT, **changes) if changes else DEFAULT


@dataclass
class CaseResult:
    row: dict[str, object]
    curve_t: list[float]
    curve_coverage: list[float]


def cases(rules: Sequence[str], worlds: Sequence[str], seeds: int, duration: float, substeps: int = 8, *,
          start_radius: float = START_RADIUS_M, start_heading_deg: float = START_HEADING_DEG,
          perturb: Sequence[tuple[str, float]] = ()) -> list[Case]:
    """Every combination, in table order: rules, then world, then seed 0..seeds-1."""
    return [Case(r, w, s, duration, substeps, start_radius, start_heading_deg, tuple(perturb))
            for r in rules for w in worlds for s in range(seeds)]


def prepare(case: Case, world=None):  # type: ignore[no-untyped-def]
    """(world with the run's start, the plant's params) of a case (world: overriding case.world)."""
    from host_sim.physics.params import DEFAULT
    from host_sim.physics.world import world_by_name_or_path

    if world is None:
        world = world_by_name_or_path(case.world, DEFAULT.body_radius)
    params = draw_params(case)
    start = draw_start(case, world, params.body_radius)
    return (world if start == world.start else world.with_changes(start=start)), params


def simulate(case: Case, world=None):  # type: ignore[no-untyped-def]
    """The fixed-step SIL run of one case (world: a World overriding case.world, e.g. another start)."""
    from host_sim.controller.hardware_io import RULE_SETS
    from host_sim.physics.params import DEFAULT
    from host_sim.controller.sil import SilController
    from host_sim.loops.simulation import Simulation

    world, params = prepare(case, world)
    controller = SilController(RULE_SETS[case.rules], params=DEFAULT)  # the firmware knows the nominal robot
    try:
        return Simulation(world, params, controller, seed=case.seed, substeps=case.substeps).run_fixed(case.duration)
    finally:
        controller.close()


def moved_in_last(t: np.ndarray, pose: np.ndarray, window_s: float = STUCK_WINDOW_S) -> float:
    """How far (m) the centre got from where it was `window_s` before the end (the whole run if shorter)."""
    if len(t) == 0:
        return 0.0
    first = int(np.searchsorted(t, t[-1] - window_s, side="left"))
    xy = pose[first:, :2]
    return float(np.max(np.hypot(*(xy - xy[0]).T)))


def row_from_result(case: Case, result, world=None) -> dict[str, object]:  # type: ignore[no-untyped-def]
    """The table row of one run (world: as given to simulate)."""
    t90 = result.time_to(0.9)
    moved = moved_in_last(result.t, result.pose)
    world, params = prepare(case, world)
    return {
        "rules": case.rules, "world": case.world, "seed": case.seed, "duration_s": case.duration,
        "start_x_m": round(world.start[0], 6), "start_y_m": round(world.start[1], 6),
        "start_phi_rad": round(world.start[2], 6),
        "coverage_end": round(float(result.coverage[-1]), 6) if len(result.coverage) else 0.0,
        "t90_s": None if t90 is None else round(t90, 3),
        "exit_found": result.exit_time is not None,
        "exit_time_s": None if result.exit_time is None else round(result.exit_time, 3),
        "collisions": int(result.collisions),
        # a robot that left through the exit is off the map, not stuck
        "stuck": result.exit_time is None and moved < STUCK_DISTANCE_M,
        "moved_last_window_m": round(moved, 4),
        **{name: float(f"{getattr(params, name):.6g}") for name, _rel in case.perturb},
    }


def run_case(case: Case) -> CaseResult:
    """One case, start to row: what a Dask worker runs."""
    result = simulate(case)
    step = max(1, int(round(CURVE_PERIOD_S / 0.040)))
    return CaseResult(row_from_result(case, result), [float(v) for v in result.t[::step]],
                      [float(v) for v in result.coverage[::step]])


def _client(scheduler: str | None, workers: int | None):  # type: ignore[no-untyped-def]
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler, timeout="10s"), None
    # The workers are spawned with SIGINT ignored and inherit it: a terminal's Ctrl-C reaches the whole
    # process group, and the parent alone answers it, shutting them down (tests/test_sweep.py::test_ctrl_c_is_one_line).
    # Their logs stop short of CRITICAL: a worker whose scheduler went away in that shutdown logs its lost
    # heartbeat as an ERROR, while a run that fails reaches the client as its exception all the same.
    with _sigint_ignored():
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.CRITICAL)
        return Client(cluster), cluster


@contextlib.contextmanager
def _quiet_shutdown() -> Iterator[None]:
    """Dask's logs silenced and SIGINT ignored while a cluster shuts down after an interrupt."""
    log = logging.getLogger("distributed")
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        with _sigint_ignored():
            yield
    finally:
        log.setLevel(level)


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored within (by this process and the processes it starts meanwhile)."""
    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers can only be set from the main thread
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def run_cases(todo: Sequence[Case], scheduler: str | None = None, workers: int | None = None,
              progress: Callable[[int], None] | None = None) -> list[CaseResult]:
    """Every case, on a fresh local cluster or the given Dask scheduler; results in the order of `todo`."""
    from dask.distributed import as_completed

    client, cluster = _client(scheduler, workers)
    interrupted = False
    try:
        futures = client.map(run_case, list(todo), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[CaseResult | None] = [None] * len(futures)
        for future in as_completed(futures):
            results[index[future.key]] = future.result()
            if progress:
                progress(1)
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        # Cut short, the runs are cancelled on purpose: the shutdown has nothing to report, and a second
        # Ctrl-C must not break it off half way (tests/test_sweep.py::test_ctrl_c_is_one_line).
        with _quiet_shutdown() if interrupted else contextlib.nullcontext():
            client.close()
            if cluster is not None:
                cluster.close()
    return [r for r in results if r is not None]


def write_table(path: str | Path, rows: Sequence[dict[str, object]], columns: Sequence[str] = COLUMNS) -> Path:
    """A CSV, a row per entry; None is written as an empty cell."""
    path = Path(path)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(columns))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row[k] is None else row[k] for k in columns})
    return path


SUMMARY_COLUMNS = ("rules", "world", "runs", "coverage_mean", "coverage_std", "reached_90_rate", "t90_median_s",
                   "exit_rate", "exit_time_median_s", "collisions_mean", "stuck_rate")


def summarise(rows: Sequence[dict[str, object]]) -> list[dict[str, Any]]:
    """A row per rule set x world: means, rates and medians over the seeds."""
    out = []
    for key in dict.fromkeys((r["rules"], r["world"]) for r in rows):
        group = [r for r in rows if (r["rules"], r["world"]) == key]
        cov = np.array([r["coverage_end"] for r in group], dtype=float)
        t90 = [float(r["t90_s"]) for r in group if r["t90_s"] is not None]  # type: ignore[arg-type]
        exits = [float(r["exit_time_s"]) for r in group if r["exit_time_s"] is not None]  # type: ignore[arg-type]
        out.append({
            "rules": key[0], "world": key[1], "runs": len(group),
            "coverage_mean": round(float(cov.mean()), 4), "coverage_std": round(float(cov.std()), 4),
            "reached_90_rate": round(len(t90) / len(group), 4),
            "t90_median_s": round(float(np.median(t90)), 2) if t90 else None,
            "exit_rate": round(len(exits) / len(group), 4),
            "exit_time_median_s": round(float(np.median(exits)), 2) if exits else None,
            "collisions_mean": round(float(np.mean([r["collisions"] for r in group])), 3),
            "stuck_rate": round(sum(bool(r["stuck"]) for r in group) / len(group), 4),
        })
    return out


def save_coverage_plot(path: str | Path, results: Sequence[CaseResult]) -> Path:
    """Coverage against time: a panel per world, per rule set the mean over seeds and its 10-90 % band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    worlds = list(dict.fromkeys(str(r.row["world"]) for r in results))
    rules = list(dict.fromkeys(str(r.row["rules"]) for r in results))
    fig, axes = plt.subplots(1, len(worlds), figsize=(5 * len(worlds), 3.8), squeeze=False, sharey=True)
    for ax, world in zip(axes[0], worlds):
        for rule in rules:
            group = [r for r in results if r.row["world"] == world and r.row["rules"] == rule]
            if not group:
                continue
            n = min(len(r.curve_coverage) for r in group)
            t = np.asarray(group[0].curve_t[:n])
            cov = 100 * np.array([r.curve_coverage[:n] for r in group])
            line, = ax.plot(t, cov.mean(axis=0), label=f"{rule} (mean of {len(group)})")
            ax.fill_between(t, *np.percentile(cov, [10, 90], axis=0), color=line.get_color(), alpha=0.25)
        ax.axhline(90, color="grey", lw=0.8, ls="--")
        ax.set(title=world, xlabel="simulated time (s)", ylim=(0, 100))
        ax.legend(loc="lower right", fontsize=8)
    axes[0][0].set_ylabel("coverage of the free area (%)\nmean, 10-90 % band")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


