"""`twinbot sweep`: same rows wherever the runs go; the table, the summary and the plot; stuck and exit.

The location test runs the real command twice, on its own local cluster
(--workers 2) and on a separate Dask LocalCluster reached through
--scheduler, and asks for byte-identical tables.
"""
from __future__ import annotations

import csv
import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from host_sim.loops import sweep
from host_sim.loops.simulation import RunResult
from host_sim.physics.world import builtin_world
from tests.helpers import REPO

PERTURB = "wheel_radius=0.02,coulomb_friction=0.2"
TINY = ["sweep", "--rules", "first,refined", "--world", "paper_room", "--seeds", "2", "--duration", "5",
        "--perturb", PERTURB]


def twinbot(args: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tools.cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=120)


@pytest.fixture(scope="module")
def local_and_cluster(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    from dask.distributed import LocalCluster

    local, remote = tmp_path_factory.mktemp("local"), tmp_path_factory.mktemp("cluster")
    r = twinbot([*TINY, "--workers", "2", "--out", str(local)])
    assert r.returncode == 0, r.stderr
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster:
        r = twinbot([*TINY, "--scheduler", cluster.scheduler_address, "--out", str(remote)])
    assert r.returncode == 0, r.stderr
    return local, remote


def test_rows_do_not_depend_on_where_the_runs_went(local_and_cluster: tuple[Path, Path]) -> None:
    local, remote = local_and_cluster
    table = (local / "runs.csv").read_text()
    assert table == (remote / "runs.csv").read_text()
    rows = list(csv.DictReader(table.splitlines()))
    assert [(r["rules"], r["seed"]) for r in rows] == [("first", "0"), ("first", "1"), ("refined", "0"),
                                                       ("refined", "1")]
    # the two rule sets explore differently; the seed changes the noise, so the paths differ
    assert rows[0]["moved_last_window_m"] != rows[2]["moved_last_window_m"]
    assert rows[0]["moved_last_window_m"] != rows[1]["moved_last_window_m"]
    # each seed its own start and robot, the same for both rule sets (a paired comparison)
    drawn = ("start_x_m", "start_y_m", "start_phi_rad", "wheel_radius", "coulomb_friction")
    assert [rows[0][k] for k in drawn] == [rows[2][k] for k in drawn]
    assert all(rows[0][k] != rows[1][k] for k in drawn)


def test_table_summary_and_plot_are_written(local_and_cluster: tuple[Path, Path]) -> None:
    local, _ = local_and_cluster
    with (local / "runs.csv").open() as f:
        assert tuple(csv.DictReader(f).fieldnames or ()) == sweep.COLUMNS + ("wheel_radius", "coulomb_friction")
    with (local / "summary.csv").open() as f:
        summary = list(csv.DictReader(f))
    assert tuple(summary[0]) == sweep.SUMMARY_COLUMNS
    assert [(s["rules"], s["world"], s["runs"]) for s in summary] == [("first", "paper_room", "2"),
                                                                      ("refined", "paper_room", "2")]
    png = (local / "coverage.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000


def test_a_run_started_at_the_exit_finds_it() -> None:
    case = sweep.Case("refined", "paper_room", 0, 5.0)
    at_exit = builtin_world("paper_room").with_changes(start=(1.8, 1.2, 0.0))  # facing the gap in the right wall
    row = sweep.row_from_result(case, sweep.simulate(case, world=at_exit))
    assert row["exit_found"] is True and 0.0 < row["exit_time_s"] < 5.0  # type: ignore[operator]
    assert row["stuck"] is False
    trapped = sweep.row_from_result(case, sweep.simulate(case))  # 5 s in the start pocket: no way out yet
    assert trapped["exit_found"] is False and trapped["exit_time_s"] is None


def handmade(xy: np.ndarray, exit_time: float | None = None, seconds: float = 40.0) -> RunResult:
    t = np.arange(len(xy)) * seconds / (len(xy) - 1)
    pose = np.column_stack([xy, np.zeros(len(xy))])
    return RunResult(t=t, pose=pose, cmd=np.zeros((len(t), 2)), coverage=np.linspace(0, 0.95, len(t)),
                     collisions=3, wall_seconds=1.0, sim_seconds=seconds, mode="fixed", controller="SIL",
                     steps=0, exit_time=exit_time)


def test_stuck_means_under_5_cm_in_the_last_20_s() -> None:
    case = sweep.Case("first", "maze", 7, 40.0)
    n = 1001  # 40 s at 0.04 s
    moving_then_still = np.column_stack([np.minimum(np.linspace(0, 2, n), 0.9), np.zeros(n)])  # stops at 18 s
    row = sweep.row_from_result(case, handmade(moving_then_still))
    assert row["stuck"] is True and row["moved_last_window_m"] == 0.0
    creeping = moving_then_still.copy()
    creeping[-1, 1] = 0.06  # 6 cm off at the very end: not stuck
    assert sweep.row_from_result(case, handmade(creeping))["stuck"] is False
    jiggling = moving_then_still.copy()
    jiggling[-400:, 1] = 0.04 * np.sin(np.arange(400))  # within 4 cm: stuck
    assert sweep.row_from_result(case, handmade(jiggling))["stuck"] is True
    gone = sweep.row_from_result(case, handmade(moving_then_still, exit_time=12.5))
    assert gone["stuck"] is False and gone["exit_found"] is True and gone["exit_time_s"] == 12.5
    assert row["t90_s"] == pytest.approx(0.9 / 0.95 * 40, abs=0.05) and row["collisions"] == 3


def test_summary_rates_and_medians() -> None:
    def row(rules: str, cov: float, exit_s: float | None, stuck: bool) -> dict[str, object]:
        return {"rules": rules, "world": "maze", "coverage_end": cov, "t90_s": 50.0 if cov >= 0.9 else None,
                "exit_time_s": exit_s, "collisions": 2, "stuck": stuck}

    rows = [row("first", 0.5, None, True), row("first", 0.95, 30.0, False), row("first", 0.95, 50.0, False),
            row("refined", 0.92, 10.0, False)]
    first, refined = sweep.summarise(rows)
    assert (first["runs"], refined["runs"]) == (3, 1)
    assert first["coverage_mean"] == pytest.approx(0.8) and first["reached_90_rate"] == pytest.approx(2 / 3, abs=1e-4)
    assert first["exit_rate"] == pytest.approx(2 / 3, abs=1e-4) and first["exit_time_median_s"] == 40.0
    assert first["stuck_rate"] == pytest.approx(1 / 3, abs=1e-4) and refined["stuck_rate"] == 0.0


def test_each_seed_starts_near_the_worlds_start_clear_of_the_walls() -> None:
    from host_sim.physics.params import DEFAULT

    maze = builtin_world("maze")  # its start is 15 cm from two walls: some draws must be refused
    starts = [sweep.draw_start(sweep.Case("refined", "maze", seed, 1.0, start_radius=0.05, start_heading_deg=15.0),
                               maze, DEFAULT.body_radius) for seed in range(300)]
    xy = np.array([s[:2] for s in starts])
    offset = np.hypot(*(xy - maze.start[:2]).T)
    turn = np.degrees([s[2] - maze.start[2] for s in starts])
    assert offset.max() <= 0.05 and offset.mean() > 0.025  # uniform over the disc: mean 2/3 of the radius
    assert np.abs(turn).max() <= 15.0 and np.abs(turn).mean() > 5.0
    assert maze.nearest_wall(xy)[0].min() >= DEFAULT.body_radius + sweep.START_CLEARANCE_M
    assert len(set(starts)) == 300
    fixed = sweep.Case("refined", "maze", 3, 1.0)  # no jitter: the world's own start
    assert sweep.draw_start(fixed, maze, DEFAULT.body_radius) == maze.start


def test_perturbed_parameters_are_drawn_within_their_range_and_drive_the_plant() -> None:
    from host_sim.physics.params import DEFAULT

    both = [sweep.draw_params(sweep.Case("first", "arena", s, 1.0, perturb=(("wheel_radius", 0.1),
                                                                           ("coulomb_friction", 0.5))))
            for s in range(100)]
    r = np.array([p.wheel_radius for p in both]) / DEFAULT.wheel_radius - 1
    assert np.abs(r).max() <= 0.1 and r.std() > 0.04  # uniform on +-10 %: sd 5.8 %
    assert len({p.coulomb_friction for p in both}) == 100
    alone = sweep.draw_params(sweep.Case("first", "arena", 7, 1.0, perturb=(("wheel_radius", 0.1),)))
    assert alone.wheel_radius == both[7].wheel_radius  # a stream per name: adding another changes nothing
    assert alone.coulomb_friction == DEFAULT.coulomb_friction
    # the plant gets them: bigger wheels at the same firmware set-points go farther
    seeds = [s for s in range(20) if sweep.draw_params(sweep.Case("first", "arena", s, 1.0,
                                                                  perturb=(("wheel_radius", 0.3),))).wheel_radius
             > 1.2 * DEFAULT.wheel_radius]
    big = sweep.Case("first", "arena", seeds[0], 2.0, perturb=(("wheel_radius", 0.3),))
    small = sweep.Case("first", "arena", seeds[0], 2.0)
    far = sweep.simulate(big).pose
    near = sweep.simulate(small).pose
    assert np.hypot(*(far[-1, :2] - far[0, :2])) > 1.1 * np.hypot(*(near[-1, :2] - near[0, :2]))


def test_ctrl_c_is_one_line(tmp_path: Path) -> None:
    """A terminal's Ctrl-C (SIGINT to the whole process group) mid-sweep: one line, status 130, no output."""
    import os
    import signal
    import time

    out = tmp_path / "o"
    sweep_cmd = [sys.executable, "-m", "tools.cli.main", "sweep", "--rules", "first", "--world", "maze", "--seeds",
                 "8", "--duration", "36000", "--workers", "2", "--out", str(out)]
    # A suite started in the background (`nohup ... &`) hands its children SIGINT ignored, and Python then
    # keeps it ignored; a terminal's Ctrl-C is what this test means, so the sweep gets SIGINT's default.
    proc = subprocess.Popen(sweep_cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # into the runs (a Ctrl-C while the workers start is ignored, so repeat it until it lands); the runs last
        # far longer than the ceiling (8 x 10 sim h: minutes idle), so a slow start on a loaded machine cannot
        # let them finish before a Ctrl-C lands
        time.sleep(4)
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                pass
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "ERROR" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) <= 2 and lines[-1].startswith("twinbot sweep: interrupted: "), err
    assert not out.exists()
