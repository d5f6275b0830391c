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

from host_sim import sweep
from host_sim.simulation import RunResult
from host_sim.world import builtin_world
from tests.helpers import REPO

TINY = ["sweep", "--rules", "first,refined", "--world", "paper_room", "--seeds", "2", "--duration", "5"]


def twinbot(args: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tools.cli", *args], cwd=REPO, capture_output=True, text=True,
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


def test_table_summary_and_plot_are_written(local_and_cluster: tuple[Path, Path]) -> None:
    local, _ = local_and_cluster
    with (local / "runs.csv").open() as f:
        assert tuple(csv.DictReader(f).fieldnames or ()) == sweep.COLUMNS
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
