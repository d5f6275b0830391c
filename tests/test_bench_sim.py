"""Smoke test of `twinbot bench sim` with tiny sizes: it runs, prints its table, runs IR-SIM, writes its JSON.

No speed is asserted: benchmarks are not timed tests.
"""
from __future__ import annotations

import json
import math

import pytest

from tools.bench import sim as bench_sim
from tools.cli import main as cli

pytest.importorskip("irsim")


@pytest.fixture
def bench_only(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cli, "SUBCOMMANDS", tuple(s for s in cli.SUBCOMMANDS if s[0] == "bench"))


def test_help_names_the_workloads(bench_only: None, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["bench", "--help"])
    assert exc.value.code == 0
    assert "sim" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        cli.main(["bench", "sim", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for word in ("--seconds", "--batch-n", "--repeats", "--json", "IR-SIM", "robot-step", "SIL", "replay"):
        assert word in out


def test_bench_sim_smoke(bench_only: None, tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    out_json = tmp_path / "bench.json"
    rc = cli.main(["bench", "sim", "--seconds", "1", "--batch-n", "8", "--batch-seconds", "0.2",
                   "--repeats", "1", "--json", str(out_json)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    out = captured.out
    assert "command:     twinbot bench sim --seconds 1 --batch-n 8 --batch-seconds 0.2 --repeats 1" in out

    lines = out.splitlines()
    header = next(ln for ln in lines if ln.startswith("workload"))
    for col in ("sim s", "wall s", "real-time factor", "robot-periods/s", "robot-steps/s"):
        assert col in header
    rows = {ln.split("|")[0].strip(): [c.strip() for c in ln.split("|")[1:]] for ln in lines[lines.index(header) + 2:]
            if "|" in ln}
    report = json.loads(out_json.read_text())
    version = report["results"]["irsim"]["version"]
    for label in (bench_sim.ROW_REPLAY, bench_sim.ROW_SIL, bench_sim.ROW_SIL_BEAM.format(rays=bench_sim.BEAM_RAYS),
                  bench_sim.ROW_BATCH.format(n=8),
                  bench_sim.ROW_BATCH_IR.format(n=8), bench_sim.ROW_IRSIM.format(version=version)):
        assert label in rows, label
        assert len(rows[label]) == 5 and rows[label][0] != "not run"
    assert rows[bench_sim.ROW_REPLAY][0] == "1.0"
    assert rows[bench_sim.ROW_BATCH.format(n=8)][0] == "0.2 x 8"

    # IR-SIM really ran, on the same walls, and stepped the robot.
    irsim = report["results"]["irsim"]
    assert irsim["steps"] == 24 and irsim["wall_s"] > 0 and math.isfinite(irsim["rtf"])
    assert irsim["scene_check_max_range_error_m"] < 1e-9
    assert "lidar2d" in irsim["yaml"] and irsim["yaml"].count("linestring") == 8
    assert irsim["end_distance_from_ours_m"] < 0.05

    # Targets: one line each, marked; the replay reproduces its recording.
    assert "targets:" in out
    names = {t["name"] for t in report["targets"]}
    assert {"replay_rtf", "sil_rtf", "batch_robot_steps", "batch_ir_robot_steps", "faster_than_irsim"} <= names
    for t in report["targets"]:
        assert t["met"] in (True, False)
    assert out.count("[MET]") + out.count("[MISSED]") == len(report["targets"])
    assert report["results"]["replay"]["reproduces_recording"] is True
    b = report["results"]["batch_ir"]
    assert b["robot_steps_per_s"] == pytest.approx(8 * b["robot_periods_per_s"])
    assert "robot-step:" in out
    assert report["results"]["sil_beam"]["beam_rays"] == bench_sim.BEAM_RAYS and "(b) beam:" in out
