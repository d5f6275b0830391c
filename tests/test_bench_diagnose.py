"""`twinbot bench diagnose`: the scorer on hand-made answers, and a three-case suite end to end.

The scorer is proven on synthetic diagnoses (right, wrong side, wrong name, missed, wrong parameter) so that
its logic does not depend on how good the diagnosis is today.  The suite run checks the scoreboard's
structure, not its figures (docs/proving-ground.md, "The blind suite").
"""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from host_sim.physics.params import DEFAULT
from host_sim.recordings.recording import load_recording
from host_sim.physics.world import world_from_dict
from tools.bench import diagnose as bench_diagnose
from tools.cli import main as cli
from tools.bench import diagnose_scoring as scoring
from tools.reference_plant.robot_model import datasheet_spec

pytest.importorskip("pysindy")

# the datasheet robot (no rolling caster, rigid tyres): the hand-computed conversions below are its own
PLANT = {k: (list(v) if isinstance(v, tuple) else v) for k, v in datasheet_spec().__dict__.items()}
SEED = 168  # dry_friction on the left wheel; the suite of 3 adds a control and a floor_slope case


OUTSIDE_THE_LIBRARY = ("floor_slope", "adc_clipping", "eccentric_wheel", "cable_drag", "encoder_drift",
                       "weakening_motor")


def key(effects: list[dict[str, Any]], plant: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"case": "case_9999", "effects": effects, "plant": plant or PLANT}


def concealed(name: str, param: str, value: float, absent: float, **site: Any) -> dict[str, Any]:
    return {"name": name, "in_library": name not in OUTSIDE_THE_LIBRARY, "params": {param: {"value": value, "unit": "-",
                                                                                "absent": absent}}, **site}


def diag(verdict: str, effects: list[tuple[str, dict[str, Any], str, float]] = (),  # type: ignore[assignment]
         located: tuple[str, ...] = (), unexplained: tuple[str, ...] = ()) -> dict[str, Any]:
    return {"verdict": verdict,
            "effects": [{"name": n, **site, "params": {p: {"value": v, "unit": "-", "ci95": None}}}
                        for n, site, p, v in effects],
            "located": [{"channel": c} for c in located], "unexplained": [{"channel": c} for c in unexplained],
            "fit": {"before": {"wheel_l": 40.0, "wheel_r": 95.0}, "after": {"wheel_l": 96.0, "wheel_r": 97.0}}}


DRY = concealed("dry_friction", "coulomb_friction", 0.0030, 0.0015, wheel="left")  # 1.5 mN m beyond nominal


@pytest.fixture(scope="module")
def suite(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("suite")
    report = out / "report.json"
    rc = cli.main(["bench", "diagnose", "--cases", "3", "--seed", str(SEED), "--duration", "30", "--jobs", "2",
                   "--workers", "2", "--out", str(out / "cases"), "--json", str(report), "--quiet"])
    assert rc == 0
    return {"out": out / "cases", "report": json.loads(report.read_text())}


# --------------------------------------------------------------------------- #
# The scorer on hand-made answers
# --------------------------------------------------------------------------- #
def test_a_right_diagnosis_scores_right(suite: dict[str, Any]) -> None:
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    right = diag("explained", [("dry_friction", {"wheel": "left"}, "dry_friction", 0.0014)], located=("wheel_l",))
    row = scoring.score_case(key([DRY]), right, rec, DEFAULT)
    assert row["outcome"] == "right" and row["kind"] == "in library"
    (score,) = row["effects"]
    assert score["named"] and score["truth"] == "dry_friction(left) coulomb_friction=0.003 -"
    assert score["param"]["true"] == pytest.approx(0.0015)  # the library holds the delta from the nominal 1.5 mN m
    assert score["param"]["error"] == pytest.approx(0.1 / 1.5)
    assert row["fit_before"] == 40.0 and row["fit_after"] == 96.0  # the worse wheel


@pytest.mark.parametrize("answer, outcome", [
    (diag("explained", [("dry_friction", {"wheel": "right"}, "dry_friction", 0.0015)]), "wrong side"),
    (diag("explained", [("dry_friction", {"wheel": "both"}, "dry_friction", 0.0015)]), "wrong side"),
    (diag("explained", [("viscous_friction", {"wheel": "left"}, "viscous_friction", 1e-4),
                        ("dry_friction", {"wheel": "left"}, "dry_friction", 0.0015)]), "wrong name"),
    (diag("unexplained", located=("wheel_l",)), "unexplained"),
    (diag("match"), "missed"),
    (None, "error"),
])
def test_wrong_diagnoses_score_wrong(suite: dict[str, Any], answer: dict[str, Any] | None, outcome: str) -> None:
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    row = scoring.score_case(key([DRY]), answer, rec, DEFAULT, None if answer else "error: boom")
    assert row["outcome"] == outcome
    assert not any(e["named"] or "param" in e for e in row["effects"])
    named = [f["name"] + f"({f['wheel']})" for f in (answer or {"effects": []})["effects"]]
    assert row["not_concealed"] == [n for n in named if n != "dry_friction(left)"]


def test_every_name_that_was_not_concealed_is_counted(suite: dict[str, Any]) -> None:
    """Beside a right name, on a control, or for an out-of-library effect: each name no concealed effect has
    (by name and site) is listed, and the totals count the cases that give one."""
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    beside = diag("explained", [("dry_friction", {"wheel": "left"}, "dry_friction", 0.0014),
                                ("track_width", {}, "half_axle", 0.05)])
    row = scoring.score_case(key([DRY]), beside, rec, DEFAULT)
    assert row["outcome"] == "right" and row["not_concealed"] == ["track_width"]
    assert scoring.score_case(key([DRY]), diag("explained", [("dry_friction", {"wheel": "left"}, "dry_friction",
                                                                0.0014)]), rec, DEFAULT)["not_concealed"] == []
    control = scoring.score_case(key([]), diag("explained", [("mass", {}, "mass", 0.5)]), rec, DEFAULT)
    tilt = scoring.score_case(key([concealed("floor_slope", "floor_tilt", 0.01, 0.0)]),
                              diag("partly explained", [("mass", {}, "mass", 0.5)]), rec, DEFAULT)
    assert control["not_concealed"] == tilt["not_concealed"] == ["mass"]
    rows = [{**r, "fit_before": 50.0, "sindy": {"error": "-"}, "seconds_per_90s": 1.0, "cpu_seconds_per_90s": 1.0,
             "excitation": "manoeuvre", "rule_set": None} for r in (row, control, tilt)]
    t = bench_diagnose.totals(rows)
    assert t["naming_not_concealed"] == 3 and t["diagnosed"] == 3
    assert t["naming_not_concealed_by_kind"] == {"control": 1, "in library": 1, "out of library": 1}


def test_a_total_read_as_a_delta_is_a_wrong_parameter(suite: dict[str, Any]) -> None:
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    row = scoring.score_case(key([DRY]), diag("explained", [("dry_friction", {"wheel": "left"}, "dry_friction",
                                                             0.0030)]), rec, DEFAULT)
    assert row["outcome"] == "right" and row["effects"][0]["param"]["error"] == pytest.approx(1.0)
    assert row["effects"][0]["param"]["error"] > scoring.PARAM_TOLERANCE



VISCOUS = concealed("viscous_friction", "viscous_friction", 4e-4, 2e-4, wheel="right")  # 0.2 beyond nominal
DELAY = concealed("actuator_delay", "actuator_delay", 0.03, 0.0)


@pytest.mark.parametrize("answer, outcome, named", [
    # both among the first two, in either order; a third after them is not judged
    (diag("explained", [("viscous_friction", {"wheel": "right"}, "viscous_friction", 1.8e-4),
                        ("dry_friction", {"wheel": "left"}, "dry_friction", 0.0015)]), "right", [True, True]),
    (diag("explained", [("dry_friction", {"wheel": "left"}, "dry_friction", 0.0015),
                        ("viscous_friction", {"wheel": "right"}, "viscous_friction", 1.8e-4),
                        ("mass", {}, "mass", 0.5)]), "right", [True, True]),
    # one named: partly; the other named only third, after a wrong second: still partly
    (diag("partly explained", [("dry_friction", {"wheel": "left"}, "dry_friction", 0.0015)]), "partly named",
     [True, False]),
    (diag("explained", [("dry_friction", {"wheel": "left"}, "dry_friction", 0.0015), ("mass", {}, "mass", 0.5),
                        ("viscous_friction", {"wheel": "right"}, "viscous_friction", 1.8e-4)]), "partly named",
     [True, False]),
    (diag("explained", [("dry_friction", {"wheel": "right"}, "dry_friction", 0.0015),
                        ("viscous_friction", {"wheel": "left"}, "viscous_friction", 1.8e-4)]), "wrong side",
     [False, False]),
    (diag("explained", [("mass", {}, "mass", 0.5)]), "wrong name", [False, False]),
    (diag("unexplained", located=("wheel_l",)), "unexplained", [False, False]),
])
def test_two_concealed_effects_are_each_sought_among_the_first_two(
        suite: dict[str, Any], answer: dict[str, Any], outcome: str, named: list[bool]) -> None:
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    row = scoring.score_case(key([DRY, VISCOUS]), answer, rec, DEFAULT)
    assert row["outcome"] == outcome
    assert [e["named"] for e in row["effects"]] == named
    assert ["param" in e for e in row["effects"]] == named  # a parameter error only where named
    if outcome == "right":
        assert [e["param"]["error"] for e in row["effects"]] == pytest.approx([0.0, 0.1])
    assert row["truth"] == "dry_friction(left) coulomb_friction=0.003 - + viscous_friction(right) " \
                           "viscous_friction=0.0004 -"


def test_a_pair_is_judged_on_what_the_recording_shows(suite: dict[str, Any]) -> None:
    """A current limit the references never reach beside a shown delay: the case is right when the delay is
    named, and the totals count the one excited effect."""
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    limit = concealed("current_limit", "current_limit", 1.01 * float(np.abs(rec.cmd).max()), 0.5)
    row = scoring.score_case(key([limit, DELAY]), diag("explained", [("actuator_delay", {}, "delay", 0.031)]),
                             rec, DEFAULT)
    assert row["outcome"] == "right" and "not_excited" not in row
    assert "not_excited" in row["effects"][0] and not row["effects"][0]["named"]
    assert row["effects"][1]["named"] and row["effects"][1]["param"]["error"] == pytest.approx(1 / 30)
    single = scoring.score_case(key([DRY]), diag("match"), rec, DEFAULT)
    for r in (row, single):
        r.update(excitation="firmware", rule_set=0, sindy={"error": "not run"}, seconds_per_90s=1.0,
                 cpu_seconds_per_90s=1.0)
    t = bench_diagnose.totals([row, single])
    assert (t["in_library"], t["concealed"], t["not_excited"], t["excited"], t["named"]) == (2, 3, 1, 2, 1)
    assert t["named_by_drive"] == {"exploration (first rules)": [1, 2]}
    assert t["params_within"] == 1 and t["outcomes_excited"] == {"right": 1, "missed": 1}
    row = scoring.score_case(key([limit, DELAY]), diag("match"), rec, DEFAULT)
    assert row["outcome"] == "missed"


@pytest.mark.parametrize("effect, fitted, error", [
    # caster: mu x the caster's load m g d / x_c = 0.46 * 9.81 * 0.015 / 0.045 = 1.5042 N
    (concealed("caster_drag", "caster_friction", 0.02, 0.0), 0.02 * 1.5042, 0.0),
    # scrub: torsional (m) x the tyres' load (0.46 + 0.05) 9.81 - 1.5042 = 3.4989 N
    (concealed("turning_resistance", "torsional_friction", 5e-4, 0.0), 5e-4 * 3.4989 * 1.1, 0.1),
    # grip: the twin's mu holds with the whole weight 5.0031 N, the plant's tyres carry 3.4989 N of it
    (concealed("traction_limit", "floor_friction", 0.15, 1.0), 0.15 * 3.4989 / 5.0031, 0.0),
    (concealed("wheel_radius", "wheel_radius", 0.0215, 0.021, wheel="right"), 0.00045, 0.1),
    (concealed("encoder_scale", "ticks_per_rev", 1240.0, 1200.0, wheel="both"), 44.0, 0.1),
    (concealed("current_limit", "current_limit", 0.04, 0.5), 0.036, 0.1),  # relative to the value, not 0.46 A
    (concealed("track_width", "half_axle", 0.050, 0.048), 0.0502, 0.1),
    (concealed("ir_offset", "ir_offset", 40.0, 0.0, sensor=3), 36.0, 0.1),
])
def test_the_parameter_table_converts_to_library_terms(effect: dict[str, Any], fitted: float, error: float) -> None:
    got = scoring.parameter_error(effect, PLANT, DEFAULT, fitted)
    assert got["error"] == pytest.approx(error, abs=2e-3)


def test_the_parameter_error_is_taken_against_the_drawn_robot() -> None:
    """The truth is the drawn robot's (the datasheet's delta: 0.5 mm), the effect's size its change from the
    robot's own value (0.4 mm); the caster's rolling drag counts in the caster's drag force; an interval is
    scored for coverage of the truth."""
    radius = concealed("wheel_radius", "wheel_radius", 0.0215, 0.021, wheel="right")
    radius["params"]["wheel_radius"]["drawn"] = 0.0211
    got = scoring.parameter_error(radius, PLANT, DEFAULT, 0.0005 + 0.00004, [0.0004, 0.0006])
    assert got["true"] == pytest.approx(0.0005) and got["error"] == pytest.approx(0.1) and got["covered"]
    assert scoring.parameter_error(radius, PLANT, DEFAULT, 0.0003, [0.0002, 0.0004])["covered"] is False
    # the reported interval (with the model error) and the fit's own are scored apart, and the share of the
    # effect's size (0.3 mm) the fit's would need to reach the truth: (0.2 mm - 0.1 mm) / 0.3 mm
    both = scoring.parameter_error(radius, PLANT, DEFAULT, 0.0003, [0.0001, 0.0005], [0.0002, 0.0004])
    assert both["covered"] is True and both["covered_fit"] is False
    assert both["share_needed"] == pytest.approx(math.sqrt(0.0002 ** 2 - 0.0001 ** 2) / 0.0003)
    caster = concealed("caster_drag", "caster_friction", 0.02, 0.0)
    caster["params"]["caster_friction"]["drawn"] = 0.0
    rolling = {**PLANT, "caster_rolling": 0.004}
    assert scoring.parameter_error(caster, rolling, DEFAULT, 0.024 * 1.5042)["error"] == pytest.approx(0.0, abs=2e-3)


def test_the_conformal_quantile_is_the_ceil_of_level_n_plus_one_th_score() -> None:
    """Split-conformal: of n scores the ceil(0.95 (n + 1))-th smallest; under 19 scores no finite one holds 95 %."""
    assert bench_diagnose.conformal_quantile(list(range(19, 0, -1)), 0.95) == 19
    assert bench_diagnose.conformal_quantile(list(range(39)), 0.95) == 37
    assert bench_diagnose.conformal_quantile(list(range(18)), 0.95) == math.inf
    assert bench_diagnose.conformal_quantile([], 0.95) is None


def test_the_parameter_table_covers_both_libraries() -> None:
    """Every plant effect in the library has a row, naming the plant's parameter and the library's."""
    from host_sim.physics import effects as library
    from tools.reference_plant import effects as plant

    listed = {name for name, e in plant.EFFECTS.items() if e.in_library}
    assert set(scoring.PARAMS) == listed == set(library.LIBRARY)
    for name, row in scoring.PARAMS.items():
        assert plant.EFFECTS[name].param == row.plant_param
        assert library.LIBRARY[name].params[0].name == row.library_param


def test_controls_and_out_of_library(suite: dict[str, Any]) -> None:
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    assert scoring.score_case(key([]), diag("match"), rec, DEFAULT)["outcome"] == "right"
    assert scoring.score_case(key([]), diag("explained", [("mass", {}, "mass", 0.5)]), rec, DEFAULT)["outcome"] \
        == "false alarm"
    assert scoring.score_case(key([]), None, rec, DEFAULT, "error: boom")["outcome"] == "false alarm"
    assert scoring.score_case(key([DRY]), None, rec, DEFAULT, "refused: too still")["outcome"] == "refused"
    tilt = concealed("floor_slope", "floor_tilt", 0.01, 0.0)
    # A library name beside an out-of-library mismatch is wrong, even in a partial explanation; one given only
    # as `closest` is not a name.
    closest = {**diag("partly explained", unexplained=("heading_rate",)), "closest": {"name": "mass"}}
    for answer, outcome in ((diag("unexplained", located=("wheel_l",), unexplained=("wheel_l",)), "right"),
                            (diag("partly explained", [("mass", {}, "mass", 0.5)], unexplained=("heading_rate",)),
                             "wrong name"),
                            (closest, "right"),
                            (diag("unexplained", located=("ir_3",), unexplained=("ir_3",)), "wrong place"),
                            # a wheel's distance per count against the tracker is the drive's encoders
                            (diag("unexplained", located=("odometry_r",), unexplained=("odometry_r",)), "right"),
                            (diag("explained", [("mass", {}, "mass", 0.5)], located=("wheel_l",)), "wrong name"),
                            (diag("match"), "missed")):
        assert scoring.score_case(key([tilt]), answer, rec, DEFAULT)["outcome"] == outcome
    clipping = concealed("adc_clipping", "adc_clip", 1500.0, 4095.0)  # shows on the IR ring, not the drive
    assert scoring.score_case(key([clipping]), diag("unexplained", located=("ir_3",), unexplained=("ir_3",)), rec,
                              DEFAULT)["outcome"] == "right"


def test_not_excited_is_read_from_the_recording(suite: dict[str, Any]) -> None:
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    top = float(np.abs(rec.cmd).max())
    assert scoring.not_excited(concealed("current_limit", "current_limit", 1.01 * top, 0.5), PLANT, rec)
    assert scoring.not_excited(concealed("current_limit", "current_limit", 0.2 * top, 0.5), PLANT, rec) is None
    assert scoring.not_excited(concealed("traction_limit", "floor_friction", 1.0, 1.0), PLANT, rec)
    assert scoring.not_excited(concealed("traction_limit", "floor_friction", 0.005, 1.0), PLANT, rec) is None
    assert scoring.not_excited(DRY, PLANT, rec) is None
    # a clip at q + 0.7 counts: the plant truncates its clipped readings to q, so rows at q show it
    highest = np.maximum(rec.ir_on, rec.ir_amb).max(axis=1)
    q = next(q for q in range(int(highest.max()), 0, -1) if (highest >= q).mean() >= scoring.MIN_EXCITED_SHARE)
    assert (highest >= q + 1).mean() < scoring.MIN_EXCITED_SHARE
    assert scoring.not_excited(concealed("adc_clipping", "adc_clip", q + 0.7, 4095.0), PLANT, rec) is None
    assert scoring.not_excited(concealed("adc_clipping", "adc_clip", q + 1.7, 4095.0), PLANT, rec)
    row = scoring.score_case(key([concealed("current_limit", "current_limit", 1.01 * top, 0.5)]), diag("match"),
                             rec, DEFAULT)
    assert "not_excited" in row and row["outcome"] == "missed"  # reported apart by the totals


def test_a_limit_shown_only_against_a_wall_is_not_excited(suite: dict[str, Any]) -> None:
    """Diagnosis does not judge the drive touching a wall, so neither does the scorer's excitation."""
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    assert rec.pose is not None and rec.meta.get("world")
    world = world_from_dict(rec.meta["world"], "test")
    start = rec.meta["world"]["start"]
    rec.pose[:, :2] = (start["x"], start["y"])  # parked clear of the walls
    rec.cmd[:] = 0.01
    n = len(rec)
    burst = slice(n // 2, n // 2 + round(n / 10))  # 10 % of the periods (a drawn number of rows) ask more
    rec.cmd[burst] = 0.2
    limit = concealed("current_limit", "current_limit", 0.1, 0.5)
    assert scoring.not_excited(limit, PLANT, rec) is None
    distance, normal = world.nearest_wall(rec.pose[burst, :2])
    rec.pose[burst, :2] -= distance[:, None] * normal  # ... now while pressed against a wall
    reason = scoring.not_excited(limit, PLANT, rec)
    assert reason is not None and "0.0 % of the periods clear of the walls (10.0 % in all" in reason
    grip = concealed("traction_limit", "floor_friction", 0.005, 1.0)  # asked for everywhere
    assert scoring.not_excited(grip, PLANT, rec) is None


def test_ambient_leakage_under_a_steady_light_is_not_excited(suite: dict[str, Any]) -> None:
    rec = load_recording(next((suite["out"] / "recordings").glob("*.csv")))
    leak = concealed("ambient_leakage", "ambient_leakage", 0.1, 0.0, sensor=2)
    rec.ir_amb[:, 2] = 150 + np.random.default_rng(0).normal(0, 3, len(rec)).round()  # steady light, noisy readings
    assert "same as an ir_offset" in scoring.not_excited(leak, PLANT, rec)
    rec.ir_amb[len(rec) // 2:, 2] += 200  # a lamp switched on halfway: the leak now moves by 20 counts
    assert scoring.not_excited(leak, PLANT, rec) is None


def test_sindy_naming_criterion() -> None:
    one = [{"equation": "w_l", "term": "tanh(w_l)", "coef": -1.0}]
    assert scoring.score_sindy(key([DRY]), one)["named"]
    assert not scoring.score_sindy(key([DRY]), one + [{"equation": "w_r", "term": "w_l", "coef": 0.2}])["named"]
    assert not scoring.score_sindy(key([DRY]), [{"equation": "w_l", "term": "w_l", "coef": -1.0}])["named"]
    assert scoring.score_sindy(key([]), [])["named"]
    assert not scoring.score_sindy(key([concealed("mass", "body_mass", 0.5, 0.46)]), one)["named"]
    # two effects: each one's signature term in its own wheel's equation, and nothing else
    both = one + [{"equation": "w_r", "term": "w_r", "coef": -0.1}]
    assert scoring.score_sindy(key([DRY, VISCOUS]), both)["named"]
    assert not scoring.score_sindy(key([DRY, VISCOUS]), one)["named"]
    assert not scoring.score_sindy(key([DRY, DELAY]), one)["named"]  # a delay has no term


# --------------------------------------------------------------------------- #
# The suite end to end
# --------------------------------------------------------------------------- #
def test_a_suite_of_another_drive_draws_only_that_drives_effects() -> None:
    """--drive wheel_speed: every case's effect is one a wheel_speed robot may have, and the suite still holds
    a control and an out-of-library case."""
    from tools.reference_plant.cases import concealed_names, kinds

    seeds = bench_diagnose.compose_suite(0, 12, "wheel_speed")
    drawn = [concealed_names(s, 1, "wheel_speed") for s in seeds]
    assert [] in drawn and all(set(names) <= set(kinds("tuning", "wheel_speed")) for names in drawn)
    assert any(set(names) & {"speed_loop_kp", "speed_loop_ki", "motor_resistance", "driver_deadband"}
               for names in drawn)
    assert "current_limit" not in {n for names in drawn for n in names}


def test_the_suite_holds_a_control_and_an_out_of_library_case() -> None:
    from tools.reference_plant.cases import concealed_names

    seeds = bench_diagnose.compose_suite(SEED, 3)
    kinds = [concealed_names(s) for s in seeds]
    assert seeds[0] == SEED and [] in kinds and ["floor_slope"] in kinds and ["dry_friction"] in kinds
    assert bench_diagnose.compose_suite(SEED, 1) == [SEED]
    # --effects 2 adds a second in-library effect to the in-library case only
    pairs = [concealed_names(s, 2) for s in seeds]
    assert [] in pairs and ["floor_slope"] in pairs
    (pair,) = [p for p in pairs if len(p) == 2]
    assert pair[0] == "dry_friction" and pair[1] != "dry_friction"



def test_a_suite_of_pairs_conceals_two_effects_per_case(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--effects 2 reaches the generator: the seed's key holds its dry friction and a second effect, and the
    scoreboard says so."""
    out = tmp_path / "pairs"
    assert cli.main(["bench", "diagnose", "--cases", "1", "--seed", str(SEED), "--duration", "10", "--effects", "2",
                     "--jobs", "1", "--out", str(out), "--quiet"]) == 0
    answer = json.loads((out / "answer_keys" / f"case_{SEED:04d}.answer.json").read_text())
    assert [e["name"] for e in answer["effects"]][0] == "dry_friction" and len(answer["effects"]) == 2
    printed = capsys.readouterr().out
    assert "--effects 2" in printed and "1 with in-library effects (2 effects between them)" in printed

def test_scoreboard_structure(suite: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    report = suite["report"]
    assert len(report["cases"]) == 3 and report["duration"] == 30
    assert {r["kind"] for r in report["cases"]} == {"in library", "control", "out of library"}
    assert sorted(p.name for p in (suite["out"] / "answer_keys").iterdir()) == \
        sorted(f"case_{s:04d}.{kind}" for s in report["seeds"] for kind in ("answer.json", "truth.npz"))
    assert not list((suite["out"] / "recordings").glob("*.answer.json"))  # keys apart from the recordings
    for r in report["cases"]:
        assert r["seconds"] > 0 and "outcome" in r
        s = r["sindy"]
        assert "error" not in s, s
        assert s["n_active"] == len(s["terms"]) and s["test_windows"] > 0
        if "fit_before" in r:  # SINDy and diagnosis judge the same windows: the same nominal fit
            assert min(s["fit_before"].values()) == pytest.approx(r["fit_before"], abs=0.01)
    names = [t["name"] for t in report["targets"]]
    assert names == ["named", "params", "wheel_fit", "false_alarms", "out_of_library", "coverage", "seconds"]
    bench_diagnose.print_report(report)
    out = capsys.readouterr().out
    assert (f"command:     twinbot bench diagnose --cases 3 --seed {SEED} --split tuning --duration 30 --jobs 2 "
            "--workers 2") in out
    assert report["workers"] == 2 and "2 worker processes, 2 per diagnosis" in out
    header = next(ln for ln in out.splitlines() if ln.startswith("case "))
    assert [c.strip() for c in header.split("|")] == list(bench_diagnose.HEADER)
    assert out.count("[MET]") + out.count("[MISSED]") + out.count("[NOT RUN]") == len(report["targets"])
    # the named cases, by what drove the robot: the key's excitation and rule set
    totals = report["totals"]
    assert sum(n for _named, n in totals["named_by_drive"].values()) == totals["excited"]
    assert sum(named for named, _n in totals["named_by_drive"].values()) == totals["named"]
    for r in report["cases"]:
        answer = json.loads((suite["out"] / "answer_keys" / f"{r['case']}.answer.json").read_text())
        assert r["rule_set"] == answer["excitation"]["rule_set"] and r["excitation"] == answer["excitation"]["kind"]
    assert "named, by what drove the robot: " in out
    assert f"cases naming an effect that was not concealed (on a control, beside a right name or instead of one): " \
           f"{totals['naming_not_concealed']}/{totals['diagnosed']}" in out


def test_a_kept_suite_is_scored_again_without_diagnosing(suite: dict[str, Any], tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """--rescore reads the diagnoses --out kept, wherever the suite has moved, and scores them alike."""
    moved = tmp_path / "moved"
    shutil.copytree(suite["out"], moved)
    assert sorted(p.name for p in (moved / "diagnoses").iterdir()) == \
        sorted(f"case_{s:04d}.json" for s in suite["report"]["seeds"])
    again = tmp_path / "again.json"
    assert cli.main(["bench", "diagnose", "--rescore", str(moved), "--json", str(again)]) == 0
    report = json.loads(again.read_text())
    assert report["seeds"] == suite["report"]["seeds"] and report["duration"] == 30
    keep = ("case", "verdict", "named", "outcome", "fit_after", "cpu_seconds", "not_excited")
    assert [{k: r.get(k) for k in keep} for r in report["cases"]] == \
        [{k: r.get(k) for k in keep} for r in suite["report"]["cases"]]
    assert f"--rescore {moved}" in capsys.readouterr().out
    assert all("fit_perfect" in r for r in report["cases"] if "fit_before" in r)
    # two kept suites scored together, one after the other (the model error's share is read off the tuning ones)
    assert cli.main(["bench", "diagnose", "--rescore", str(moved), str(suite["out"]), "--json", str(again)]) == 0
    both = json.loads(again.read_text())
    assert both["seeds"] == 2 * report["seeds"] and len(both["cases"]) == 2 * len(report["cases"])
    assert both["totals"]["intervals"] == 2 * report["totals"]["intervals"]
    assert f"--rescore {moved} {suite['out']}" in capsys.readouterr().out
    # a suite kept before the truth files: scored alike, every case counted, diagnosis's ceiling shown
    for truth in (moved / "answer_keys").glob("*.truth.npz"):
        truth.rename(truth.with_suffix(".gone"))
    assert cli.main(["bench", "diagnose", "--rescore", str(moved), "--json", str(again)]) == 0
    old = json.loads(again.read_text())
    assert not any("fit_perfect" in r for r in old["cases"])
    assert old["totals"]["wheel_attainable"] == old["totals"]["wheel_judged"] and not old["totals"]["wheel_unattainable"]
    assert "(c " in capsys.readouterr().out
    for truth in (moved / "answer_keys").glob("*.truth.gone"):
        truth.rename(truth.with_suffix(".npz"))
    assert cli.main(["bench", "diagnose", "--rescore", str(moved), "--out", str(tmp_path / "new")]) == 2
    assert "give one of them" in capsys.readouterr().err
    first_key = moved / "answer_keys" / f"case_{report['seeds'][0]:04d}.answer.json"
    first_key.rename(first_key.with_suffix(".gone"))
    assert cli.main(["bench", "diagnose", "--rescore", str(moved)]) == 2
    assert first_key.name in capsys.readouterr().err
    first_key.with_suffix(".gone").rename(first_key)
    (moved / "diagnoses" / f"case_{report['seeds'][0]:04d}.json").write_text("{\"recording\": ")
    assert cli.main(["bench", "diagnose", "--rescore", str(moved)]) == 2
    assert "not a kept diagnosis" in capsys.readouterr().err
    shutil.rmtree(moved / "diagnoses")
    assert cli.main(["bench", "diagnose", "--rescore", str(moved)]) == 2
    assert "no diagnoses/case_*.json" in capsys.readouterr().err


def test_the_perfect_twin_is_the_plants_own_encoders_on_the_judged_windows(suite: dict[str, Any]) -> None:
    """The answer keys keep the plant's unrounded encoders (the recording's counts are the edges passed at
    them, each edge where the plant's uneven encoder places it), and the scorer judges them as a twin's
    prediction on the windows the diagnosis judged: no twin does better."""
    from tools.reference_plant.plant import edges_passed

    for r in suite["report"]["cases"]:
        if "fit_before" not in r:
            continue
        answer = scoring.load_key(suite["out"] / "answer_keys" / f"{r['case']}.answer.json")
        rec = load_recording(suite["out"] / "recordings" / f"{r['case']}.csv")
        exact = answer["encoders"]
        edges, drift = answer["plant"]["encoder_edges"], answer["plant"]["encoder_drift"]
        counts = [[edges_passed(x, tuple(edges[k])) + math.floor(drift[k] * t) for k, x in enumerate(row)]
                  for row, t in zip(exact, rec.t)]
        assert exact.shape == rec.enc.shape and (np.array(counts) == rec.enc).all()
        assert (np.floor(exact) == rec.enc).mean() > 0.5  # the edges sit near their even places
        assert not (exact == rec.enc).all()  # not the counts themselves
        judged = json.loads((suite["out"] / "diagnoses" / f"{r['case']}.json").read_text())["diagnosis"]["fit"]["judged"]
        assert judged and all(t1 > t0 for t0, t1 in judged)
        assert r["fit_perfect"] == scoring.perfect_twin_fit(exact, rec, judged) < 100
        assert scoring.perfect_twin_fit(rec.enc.astype(float), rec, judged) == 100.0  # the counts themselves
        # only the judged windows count: the truth elsewhere changes nothing
        elsewhere = exact.copy()
        inside = np.zeros(len(rec), dtype=bool)
        for t0, t1 in judged:
            inside |= (rec.t >= t0 - 1e-6) & (rec.t <= t1 + 1e-6)
        elsewhere[~inside] += 7.3
        assert scoring.perfect_twin_fit(elsewhere, rec, judged) == r["fit_perfect"]
        assert scoring.perfect_twin_fit(exact, rec, []) is None


def test_the_wheel_fit_target_sets_apart_what_no_twin_could_meet() -> None:
    """A case where even a perfect twin scores under the target is listed apart, not counted a miss; a case
    without the truth (a suite kept without its truth files) is counted."""
    base = {"kind": "control", "outcome": "right", "excitation": "firmware", "rule_set": 1, "fit_before": 80.0,
            "sindy": {"error": "not run"}, "seconds_per_90s": 1.0, "cpu_seconds_per_90s": 1.0}
    rows = [{**base, "case": "case_0001", "fit_after": 95.0, "fit_perfect": 97.0, "fit_ceiling": 97.5},
            {**base, "case": "case_0002", "fit_after": 88.0, "fit_perfect": 89.0},  # apart
            {**base, "case": "case_0003", "fit_after": 85.0, "fit_perfect": 96.0},  # a miss
            {**base, "case": "case_0004", "fit_after": 92.0}]  # no truth: counted
    t = bench_diagnose.totals(rows)
    assert (t["wheel_attainable_ok"], t["wheel_attainable"], t["wheel_ok"], t["wheel_judged"]) == (2, 3, 2, 4)
    assert t["wheel_unattainable"] == [{"case": "case_0002", "fit_after": 88.0, "fit_perfect": 89.0}]
    # the controls against their perfect twin: the twin under it, diagnosis's ceiling over it
    assert t["perfect_twin_controls"] == {"firmware": {"cases": 3, "twin_under_median": 2.0, "twin_under_max": 11.0,
                                                       "ceiling_over_median": 0.5, "ceiling_over_max": 0.5}}
    target = next(x for x in bench_diagnose.targets(t) if x["name"] == "wheel_fit")
    assert not target["met"] and "2/3" in target["text"] and "1 where it does not, apart; in all 2/4" in target["text"]
    assert bench_diagnose.case_row({**rows[1], "truth": "none (control)", "verdict": "match", "named": "-"})[7] == \
        "80 -> 88 (p 89)"


def test_a_case_is_labelled_by_what_drove_it() -> None:
    assert bench_diagnose.drive_label({"excitation": "manoeuvre", "rule_set": 1}) == "manoeuvre"
    assert bench_diagnose.drive_label({"excitation": "firmware", "rule_set": 0}) == "exploration (first rules)"
    assert bench_diagnose.drive_label({"excitation": "firmware", "rule_set": 1}) == "exploration (refined rules)"
    rows = [{"kind": "in library", "outcome": o, "excitation": "firmware", "rule_set": rules,
             "sindy": {"error": "not run"}, "seconds_per_90s": 1.0,
             "effects": [{"named": True, "param": {"error": 0.01}} if o == "right" else {"named": False}],
             "cpu_seconds_per_90s": 1.0}
            for o, rules in (("right", 1), ("refused", 0), ("right", 0), ("missed", 0))]
    assert bench_diagnose.totals(rows)["named_by_drive"] == {"exploration (refined rules)": [1, 1],
                                                             "exploration (first rules)": [1, 3]}


def test_the_diagnosis_is_blind(suite: dict[str, Any], tmp_path: Path) -> None:
    """Moved away from its answer key, a recording gets the same diagnosis (and in one process, as the suite's
    two per diagnosis gave)."""
    control = next(r for r in suite["report"]["cases"] if r["kind"] == "control")
    src = suite["out"] / "recordings" / f"{control['case']}.csv"
    shutil.copy(src, tmp_path / src.name)
    shutil.copy(str(src) + ".json", tmp_path / (src.name + ".json"))
    alone = bench_diagnose.diagnose_blind(str(tmp_path / src.name))
    assert alone.get("diagnosis", {}).get("verdict", alone.get("error")) == control["verdict"]
    kept = json.loads((suite["out"] / "diagnoses" / f"{control['case']}.json").read_text())
    if "diagnosis" in kept:
        assert {**alone["diagnosis"], "recording": ""} == {**kept["diagnosis"], "recording": ""}


def _located(out: Path, case: str) -> bool:
    """Whether the kept diagnosis's datasheet twin located anything: what is left located, or what the
    calibration within the tolerance took up."""
    d = json.loads((out / "diagnoses" / f"{case}.json").read_text()).get("diagnosis", {})
    return bool(d.get("located")) or bool(d.get("calibration", {}).get("located_before"))


def test_the_margins_bench_reads_the_kept_suite_and_agrees_with_the_diagnosis(suite: dict[str, Any],
                                                                               tmp_path: Path) -> None:
    """`twinbot bench margins --suite DIR` on what `bench diagnose --out DIR` kept: a row per recording, and
    a rule at 1 or more exactly where the diagnosis located something (a margin is the rules' own test)."""
    out = tmp_path / "margins.json"
    assert cli.main(["bench", "margins", "--suite", str(suite["out"]), "--json", str(out), "--quiet"]) == 0
    report = json.loads(out.read_text())
    verdicts = {r["case"]: r["verdict"] for r in suite["report"]["cases"]}
    assert sorted(r["case"] for r in report["cases"]) == sorted(verdicts)
    for row in report["cases"]:
        if "refused" in row:
            assert verdicts[row["case"]].startswith("refused")
            continue
        assert set(row["margins"]) == {"bias", "scale", "scatter", "timing", "lag"}
        reached = any(m >= 1 for m, _where in row["margins"].values())
        if "little_data" in row:  # a match on so little data is refused, a mismatch located is diagnosed
            assert reached != verdicts[row["case"]].startswith("refused"), row
        else:  # a match may still have located something, which the calibration within tolerance took up
            assert reached == _located(suite["out"], row["case"]), row
            assert reached or verdicts[row["case"]] == "match", row
    controls = [r for r in report["cases"] if r["control"] and "margins" in r]
    bias = next(s for s in report["summary"] if s["rule"] == "bias")
    assert bias["controls"] == len(controls) and report["targets"][0]["met"] == all(
        m < 1 for r in controls for m, _where in r["margins"].values())



def test_the_margins_bench_says_which_recordings_it_could_not_read_or_label(suite: dict[str, Any],
                                                                            tmp_path: Path) -> None:
    """A broken recording is listed as unreadable, one without an answer key as unlabelled; neither stops the
    bench or enters the summary."""
    copy = tmp_path / "suite"
    shutil.copytree(suite["out"], copy)
    (copy / "recordings" / "case_9998.csv").write_text("not,a,recording\n")
    first = sorted((copy / "recordings").glob("case_0*.csv"))[0]
    shutil.copy(first, copy / "recordings" / "case_9999.csv")
    shutil.copy(str(first) + ".json", copy / "recordings" / "case_9999.csv.json")
    out = tmp_path / "margins.json"
    assert cli.main(["bench", "margins", "--suite", str(copy), "--json", str(out), "--quiet"]) == 0
    rows = {r["case"]: r for r in json.loads(out.read_text())["cases"]}
    assert "error" in rows["case_9998"] and "case_9998.csv" in rows["case_9998"]["error"]
    assert rows["case_9999"]["unlabelled"] and "margins" in rows["case_9999"]
    summary = json.loads(out.read_text())["summary"]
    assert sum(s["controls"] for s in summary) == 5 * sum(1 for r in rows.values() if r["control"] and "margins" in r)


def test_the_board_controls_target_needs_every_recording_a_match() -> None:
    """Idle and oversubscribed both count: one board recording that is not a match misses the target."""
    from tools.bench.diagnose import board_target

    rows = [{"busy": 0, "verdict": "match", "late_share": 0.1}, {"busy": 6, "verdict": "match", "late_share": 0.7}]
    assert board_target(rows)["met"] is True and "2/2" in board_target(rows)["text"]
    rows[1]["verdict"] = "unexplained"
    assert board_target(rows)["met"] is False and "6 busy: unexplained, 70% rows late" in board_target(rows)["text"]
