"""Odometry (host_sim/diagnosis/odometry.py): each wheel's distance per count from the encoders against the
tracker, and the verdict it keeps from being a match (report._report_odometry).

The twin's tyres do not slip, so its recordings give the distance per count it was built with.
"""
from __future__ import annotations

import html
import re

import pytest

from host_sim.diagnosis import odometry
from host_sim.diagnosis import diagnose
from host_sim.diagnosis.html import render
from host_sim.diagnosis.report import Diagnosis, _report_odometry
from host_sim.diagnosis.tolerance import BANDS, Tolerance
from host_sim.physics.params import DEFAULT
from host_sim.recordings.recording import load_recording
from tests.test_diagnosis import ROOM, record

BIG_LEFT = DEFAULT.replace(wheel_radius_delta_l=0.04 * DEFAULT.wheel_radius)  # 4 % large: beyond its 1.5 % tolerance
FINE_RIGHT = DEFAULT.replace(wheel_radius_delta_r=0.01 * DEFAULT.wheel_radius)  # 1 %: within the tolerance
MORE_COUNTS_RIGHT = DEFAULT.replace(ticks_per_rev_delta_r=48.0)  # 1248 counts a turn, the datasheet says 1200


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for name, params in (("nominal", DEFAULT), ("big_left", BIG_LEFT), ("fine_right", FINE_RIGHT),
                         ("counts_right", MORE_COUNTS_RIGHT)):
        out[name] = record(tmp_path_factory.mktemp(name), params)
    return out


def test_a_wheel_beyond_its_tolerance_is_found_by_its_odometry_alone(runs):
    """Each wheel's distance per count as built, to within two standard errors of a few tenths of a per cent;
    beyond its tolerance only where it is: a wheel 4 % large, or an encoder with 4 % more counts a turn (3.8 %
    less far a count), not a wheel 1 % large nor the datasheet's robot."""
    band = BANDS["wheel_radius"]
    expect = {"nominal": (0.0, 0.0), "big_left": (0.04, 0.0), "fine_right": (0.0, 0.01),
              "counts_right": (0.0, 1200.0 / 1248.0 - 1.0)}
    for name, (left, right) in expect.items():
        odo = odometry.measure_odometry(runs[name], DEFAULT, ROOM)
        assert odo is not None and odo.windows >= odometry.MIN_WINDOWS
        for w, want in enumerate((left, right)):
            assert max(odo.per_count_se) < 0.005
            assert odo.per_count[w] == pytest.approx(want, abs=2 * odo.per_count_se[w] + 1e-3), (name, odo)
        assert odo.half_axle == pytest.approx(0.0, abs=0.01)
        assert odo.beyond(band) == {"big_left": [0], "counts_right": [1]}.get(name, []), (name, odo)


def test_without_a_tracker_there_is_no_odometry(runs):
    blind = load_recording(runs["big_left"].path)
    blind.pose = None
    assert odometry.measure_odometry(blind, DEFAULT, ROOM) is None


def test_a_wheel_that_goes_too_far_per_count_is_no_match(runs):
    """Beyond its tolerance, a wheel's distance per count is located and unexplained: a match becomes
    unexplained, an explanation partial; a wheel radius or encoder scale named on that wheel accounts for it."""
    tol = Tolerance(DEFAULT, dict(BANDS))
    result = Diagnosis("run", "match", [])
    _report_odometry(result, runs["counts_right"], DEFAULT, ROOM, tol)
    assert result.verdict == "unexplained" and result.odometry is not None
    (item,) = result.unexplained
    said = re.search(r"the right wheel goes ([\d.]+) % less far per encoder count", item["words"])
    assert item["channel"] == "odometry_r" and said and float(said.group(1)) == pytest.approx(3.85, abs=0.1)
    assert "encoder" in item["words"] and "radius" in item["words"]
    assert "odometry" in result.to_json() and result.located[0]["value"] == pytest.approx(-0.038, abs=0.005)
    explained = Diagnosis("run", "explained", [], effects=[{"name": "ir_gain", "sensor": 2}])
    _report_odometry(explained, runs["counts_right"], DEFAULT, ROOM, tol)
    assert explained.verdict == "partly explained" and explained.effects == [{"name": "ir_gain", "sensor": 2}]

    def scale(wheel):
        return {"name": "encoder_scale", "wheel": wheel, "params": {"encoder_scale": {"value": 48.0}}}
    named = Diagnosis("run", "explained", [], effects=[scale("right")])
    _report_odometry(named, runs["counts_right"], DEFAULT, ROOM, tol)
    assert named.verdict == "explained" and not named.unexplained and named.effects == [scale("right")]
    # both encoders' scale would make the left wheel go 3.8 % less far too, which it does not: not named
    wrong = Diagnosis("run", "explained", [], effects=[scale("both")])
    _report_odometry(wrong, runs["counts_right"], DEFAULT, ROOM, tol)
    assert wrong.verdict == "unexplained" and not wrong.effects and "encoder_scale (both)" in wrong.notes[-1]
    assert [item["channel"] for item in wrong.unexplained] == ["odometry_r"]
    # ... unless its 95 % interval reaches what the odometry shows on each wheel: 0 to 96 counts more a turn
    loose = {**scale("both"), "params": {"encoder_scale": {"value": 48.0, "ci95": [0.0, 96.0]}}}
    kept = Diagnosis("run", "explained", [], effects=[loose])
    _report_odometry(kept, runs["counts_right"], DEFAULT, ROOM, tol)
    assert kept.verdict == "explained" and kept.effects == [loose] and not kept.unexplained
    fine = Diagnosis("run", "match", [])
    _report_odometry(fine, runs["fine_right"], DEFAULT, ROOM, tol)
    assert fine.verdict == "match" and not fine.located


def test_an_effect_that_leaves_the_odometrys_mismatch_on_its_wheel_is_not_named(runs):
    """The right encoder counts 4 % more a turn, which no effect named accounts for.  An effect that answers
    for the right wheel (on it, on both, or on the robot) was fitted on a twin going the datasheet's distance
    per count there, which leaves the odometry's mismatch located: not named, the closest at most.  One on the
    left wheel or on a sensor stands."""
    tol = Tolerance(DEFAULT, dict(BANDS))

    def effect(name, gain, **site):
        return {"name": name, **site, "params": {}, "evidence": {"held_out_gain_located": gain}}
    for answering in (effect("dry_friction", 0.4, wheel="right"), effect("dry_friction", 0.4, wheel="both"),
                      effect("mass", 0.4)):
        travel = {"channel": "travel", "regime": "window by window", "spans": [[0.0, 90.0]], "words": "less far"}
        d = Diagnosis("run", "explained", [], located=[travel], effects=[answering])
        _report_odometry(d, runs["counts_right"], DEFAULT, ROOM, tol)
        assert not d.effects and d.verdict == "partly explained", (answering, d.summary())
        assert d.closest == {"name": answering["name"] + ("(right)" if answering.get("wheel") == "right" else ""),
                             "removes_percent": 40.0}
        assert "right wheel's distance per count" in d.notes[-1] and answering["name"] in d.notes[-1]
        assert [u["channel"] for u in d.unexplained] == ["travel", "odometry_r"]
    weak = Diagnosis("run", "explained", [], effects=[effect("dry_friction", 0.05, wheel="both")])
    _report_odometry(weak, runs["counts_right"], DEFAULT, ROOM, tol)
    assert weak.verdict == "unexplained" and not weak.effects, weak.summary()
    standing = [effect("dry_friction", 0.4, wheel="left"), effect("ir_gain", 0.4, sensor=2)]
    kept = Diagnosis("run", "explained", [], effects=list(standing))
    _report_odometry(kept, runs["counts_right"], DEFAULT, ROOM, tol)
    assert kept.effects == standing and kept.verdict == "partly explained" and kept.closest is None


def test_a_diagnosis_of_an_encoder_with_more_counts_is_no_match_and_its_page_says_why(runs, tmp_path):
    """End to end: the right encoder counts 4 % more a turn than the datasheet says.  Whatever the dynamics
    name, the verdict is not a match, and the HTML page carries the odometry's words where it is located."""
    d = diagnose(runs["counts_right"], DEFAULT, ROOM)
    assert d.verdict != "match" and d.odometry is not None and d.odometry.beyond(BANDS["wheel_radius"]) == [1]
    named = [e for e in d.effects
             if e["name"] in ("wheel_radius", "encoder_scale") and e.get("wheel") in ("right", "both")]
    located = [item for item in d.located if item["channel"] == "odometry_r"]
    assert bool(named) != bool(located), (d.summary(), named, located)
    page = render(runs["counts_right"], d)
    assert all(html.escape(item["words"]) in page for item in located) and "odometry" in d.to_json()
