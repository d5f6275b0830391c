"""The figure commands draw what they say (PNG files a person can open)."""
from __future__ import annotations

from tests.helpers import run_twinbot


def test_plot_sensor_draws_the_papers_figures(tmp_path):
    r = run_twinbot("plot", "sensor", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    for name in ("fig7_angle", "fig8_distance", "fig10_power", "fig11_3d_L27", "fig12_3d_L78"):
        assert (tmp_path / f"{name}.png").stat().st_size > 20000


def test_fuzzy_plot_and_fcl(tmp_path):
    r = run_twinbot("fuzzy", "--rules", "first", "--fcl")
    assert r.returncode == 0 and "FUNCTION_BLOCK twinbot_first" in r.stdout
    r = run_twinbot("fuzzy", "--plot", str(tmp_path / "sets.png"))
    assert r.returncode == 0 and (tmp_path / "sets.png").stat().st_size > 20000


def test_help_answers_for_every_command():
    r = run_twinbot("--help")
    assert r.returncode == 0
    for command in ("demo", "sim", "board", "serial", "flash", "fuzzy", "plot", "bench"):
        assert command in r.stdout
        sub = run_twinbot(command, "--help")
        assert sub.returncode == 0 and "usage: twinbot " + command in sub.stdout
