"""The verdict's rules on the test block (docs/diagnosis.md, "The test block" and "Verdict"): the block no fit
or rule sees, what "near its ceiling", "white" and "no trend" mean, an effect that removes only part of a
mismatch said as closest, parameters that change between the halves, and intervals that hold 95 %.
"""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from host_sim.diagnosis import DiagnosisError, diagnose
from host_sim.diagnosis import report as R
from host_sim.diagnosis import verdict as V
from host_sim.diagnosis.testblock import MIN_TEST_WINDOWS, TEST_FRACTION, split_test_block, window_count
from host_sim.physics import effects as E
from host_sim.physics.params import DEFAULT
from tests.helpers import run_twinbot
from tests.test_diagnosis import ROOM, record


@pytest.fixture(scope="module")
def twin_run(tmp_path_factory):
    return record(tmp_path_factory.mktemp("verdict"))


def test_the_test_block_is_the_last_quarter_and_nothing_else_sees_it(twin_run, monkeypatch):
    """The last 25 % of the 1 s windows (6 at least) are the test block: its windows are the recording's
    own, row for row; the part fitted ends on the row after its last window, and the comparison, the
    locator and any fit see that part alone."""
    n = window_count(twin_run)
    fitted, block = split_test_block(twin_run)
    n_test = max(MIN_TEST_WINDOWS, math.ceil(0.25 * n))
    assert window_count(block) == n_test and window_count(fitted) == n - n_test
    assert fitted.t[-1] == block.t[12]  # the test block's first window starts 0.5 s (12 rows) into it
    assert block.t[-1] == twin_run.t[-1]
    assert window_count(split_test_block(twin_run, 0.5)[1]) == math.ceil(0.5 * n)
    seen = []
    compare_all = R.compare_all
    monkeypatch.setattr(R, "compare_all", lambda rec, *a, **k: seen.append(rec.t[-1]) or compare_all(rec, *a, **k))
    d = diagnose(twin_run, DEFAULT, ROOM, test_block=TEST_FRACTION)
    assert seen and all(t_end == fitted.t[-1] for t_end in seen)
    assert d.verdict == "match"
    doc = d.to_json()["fit"]["test"]
    assert doc["windows"] == n_test and doc["from_s"] == pytest.approx(block.t[12])
    assert set(doc["before"]) == set(doc["after"]) and doc["before"]["wheel_l"] > 90


def test_too_short_for_a_test_block_is_refused_in_one_line(tmp_path):
    """12 windows of 1 s at least: 6 to fit, 6 to test; the refusal says how long the recording must be."""
    rec = record(tmp_path, duration=11.0)
    with pytest.raises(DiagnosisError, match=r"lasts 11\.0 s: too short to diagnose and keep a test block "
                                             r"\(at least 13 s"):
        diagnose(rec, DEFAULT, ROOM, test_block=TEST_FRACTION)
    out = run_twinbot("diagnose", str(rec.path), "--test-fraction", "0.25", "--quiet")
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1 and "at least 13 s" in out.stderr


def test_a_second_recording_is_the_test_block(tmp_path, twin_run):
    """--test REC2.csv: the whole first recording is fitted, the second judged."""
    second = record(tmp_path, duration=14.0, name="second.csv", seed=9)
    out = run_twinbot("diagnose", str(twin_run.path), "--test", str(second.path), "--quiet",
                      "--json", str(tmp_path / "v.json"))
    assert out.returncode == 0, out.stderr
    doc = json.loads((tmp_path / "v.json").read_text())
    assert doc["verdict"] == "match" and doc["fit"]["test"]["windows"] == window_count(second)
    assert doc["fit"]["test"]["from_s"] == pytest.approx(second.t[12]) and doc["fit"]["test"]["to_s"] < second.t[-1]


def test_near_its_ceiling_is_noise_plus_at_most_one_noise_level():
    """RMS <= sqrt(2) noise levels: white noise with a bias of 0.9 noise levels is near, of 1.1 is not."""
    rng = np.random.default_rng(0)
    noise = rng.normal(size=(40, 24))
    noise = (noise - noise.mean()) / noise.std()
    times = np.arange(40 * 24, dtype=float).reshape(40, 24) * 0.04
    near = V.judge_residual("vbat", noise + 0.9, 1.0, times)
    far = V.judge_residual("vbat", noise + 1.1, 1.0, times)
    assert near.near and near.rms_noise == pytest.approx(math.sqrt(1 + 0.81), rel=1e-6)
    assert not far.near and V.NEAR_NOISE == pytest.approx(math.sqrt(2))


def test_a_heavy_tailed_white_residual_is_near_its_noise():
    """White noise with rare large values (5 % at ten times the rest): its noise as a second moment makes
    its RMS one noise level; a slow residual's first differences still leave it out."""
    rng = np.random.default_rng(3)
    heavy = rng.normal(size=(40, 24)) * np.where(rng.random((40, 24)) < 0.05, 10.0, 1.0)
    assert V.second_moment_noise(heavy) == pytest.approx(np.sqrt(np.mean(heavy ** 2)), rel=0.15)
    slow = np.repeat(np.linspace(-3, 3, 40)[:, None], 24, axis=1) + 0.1 * rng.normal(size=(40, 24))
    assert V.second_moment_noise(slow) < 0.2


def test_whiteness_passes_differenced_noise_and_fails_a_slow_residual():
    """Increments of a rounded position (a lag-1 moving average) are white to the test; a slow residual
    above one noise level is not; below one noise level its structure is not asked about."""
    rng = np.random.default_rng(1)
    phase = rng.random((40, 25))
    differenced = np.diff(phase, axis=1)  # rounding errors of the ends of each period
    assert V.whiteness_p(differenced) > 0.05
    slow = np.sin(np.arange(24) / 4.0)[None, :] * np.ones((40, 1)) * 2.0 + rng.normal(size=(40, 24))
    assert V.whiteness_p(slow) < 1e-6
    times = np.arange(40 * 24, dtype=float).reshape(40, 24) * 0.04
    assert not V.judge_residual("wheel_l", slow, 1.0, times).white
    assert V.judge_residual("wheel_l", 0.3 * slow / np.sqrt(np.mean(slow ** 2)), 1.0, times).white


def test_a_residual_that_drifts_over_the_test_block_has_a_trend():
    """The windows' mean residuals regressed on time: a drift of a noise level over the block is a trend,
    noise is not."""
    rng = np.random.default_rng(2)
    times = 60.0 + np.arange(8 * 24, dtype=float).reshape(8, 24) * 0.04
    noise = rng.normal(size=(8, 24))
    assert V.judge_residual("wheel_l", noise, 1.0, times).steady
    drift = noise + np.linspace(-1.0, 1.0, 8)[:, None]
    judged = V.judge_residual("wheel_l", drift, 1.0, times)
    assert not judged.steady and judged.trend_t > 4


def _drifting(cmp, size, channel="wheel_l"):
    """cmp with a channel recorded as its twin but for a drift over the run of `size` noise levels."""
    ch = cmp.channel(channel)
    ch.y = ch.y_hat[:, 0] + size * ch.noise_floor * np.linspace(-0.5, 0.5, len(cmp.windows))[:, None]
    return cmp


def test_a_residual_that_drifts_over_the_held_out_windows_drifts(twin_run):
    """verdict.drifts: a trend of the held-out windows' mean residual, reported only where it moves the mean by
    the smallest bias the locator names (one noise level) or more."""
    from host_sim.diagnosis.compare import compare

    cmp = compare(twin_run, DEFAULT, ROOM, locate=False)
    names = ["wheel_l", "wheel_r", "travel"]
    assert V.drifts(cmp, twin_run.t, names) == []  # the twin's own recording
    assert V.drifts(_drifting(cmp, 0.5), twin_run.t, names) == []  # a trend, but under a noise level
    ((judged, change),) = V.drifts(_drifting(cmp, 3.0), twin_run.t, names)
    assert judged.channel == "wheel_l" and not judged.steady and 2.0 < change <= 3.0


def test_a_match_that_drifts_over_the_recording_is_unexplained(twin_run):
    """Without a test block, a match whose held-out windows drift (a motor that weakens, an encoder that slips
    more as the run goes on) is unexplained, with the channel and its drift in words."""
    from host_sim.diagnosis.block_verdict import judge_match_held_out
    from host_sim.diagnosis.compare import compare

    def judged(cmp):
        d = R.Diagnosis("run.csv", "match", [cmp])
        judge_match_held_out(d, twin_run.t)
        return d

    assert judged(compare(twin_run, DEFAULT, ROOM, locate=False)).verdict == "match"
    d = judged(_drifting(compare(twin_run, DEFAULT, ROOM, locate=False), 3.0))
    assert d.verdict == "unexplained" and [u["channel"] for u in d.unexplained] == ["wheel_l", "count_l"]  # its totals
    assert d.located[0]["regime"] == "over the recording" and "a drift over the recording in the left wheel" in d.summary()


def test_a_match_is_not_held_to_drift_on_its_sensors(twin_run):
    """An IR sensor's residual maps its law's error over the walls the route passed, which change over a run:
    its trend in time is not a drift of the robot, and a match is not judged on it."""
    from host_sim.diagnosis.block_verdict import judge_match_held_out
    from host_sim.diagnosis.compare import compare

    cmp = _drifting(compare(twin_run, DEFAULT, ROOM, locate=False), 3.0, "ir_0")
    assert [j.channel for j, _c in V.drifts(cmp, twin_run.t, ["ir_0"])] == ["ir_0"]  # it does trend
    d = R.Diagnosis("run.csv", "match", [cmp])
    judge_match_held_out(d, twin_run.t)
    assert d.verdict == "match" and not d.unexplained


def test_an_encoder_whose_scale_drifts_over_the_run_is_no_match(twin_run):
    """The left encoder counting 4 % less at the start and 4 % more at the end than its wheel turns: a twin
    calibrated on the whole run matches it on average, and only the drift says it is not the robot."""
    counts = np.diff(twin_run.enc[:, 0]).astype(float) * (1.0 + 0.04 * np.linspace(-1.0, 1.0, len(twin_run) - 1))
    enc_l = twin_run.enc[0, 0] + np.concatenate([[0], np.round(np.cumsum(counts))])
    enc = np.column_stack([enc_l, twin_run.enc[:, 1]]).astype(twin_run.enc.dtype)
    d = diagnose(dataclasses.replace(twin_run, enc=enc), DEFAULT, ROOM)
    assert d.verdict == "unexplained" and not d.effects, d.summary()
    assert {"wheel_l", "count_l"} & {u["channel"] for u in d.unexplained}
    assert all(u["regime"] == "over the recording" for u in d.unexplained), d.summary()


def test_a_parameter_changes_when_the_halves_differ_beyond_their_intervals():
    """|a - b| against the root sum of squares of the two 95 % half-widths."""
    assert V.changed([1.0], [1.3], [(0.9, 1.1)], [(1.2, 1.4)])
    assert not V.changed([1.0], [1.1], [(0.9, 1.1)], [(1.0, 1.2)])
    assert V.changed([1.0, 5.0], [1.0, 5.5], [(0.9, 1.1), (4.9, 5.1)], [(0.9, 1.1), (5.4, 5.6)])


def test_a_step_fits_best_where_the_residual_changes(twin_run):
    """step_window: the window where a mean before and a mean after fit the located channels best."""
    from host_sim.diagnosis.compare import compare

    cmp = compare(twin_run, DEFAULT, ROOM, locate=False)
    ch = cmp.channel("wheel_l")
    at = len(cmp.windows) // 2 + 3
    ch.y = ch.y.copy()
    ch.y[at:] += 2.0  # the robot counts two ticks a period more from window `at` on
    assert V.step_window(cmp, ["wheel_l"]) == at


def test_an_effect_that_does_not_explain_the_test_block_is_closest_not_named(tmp_path):
    """An encoder that counts 30 % more from 8 s on (outside the library): a wheel radius fitted on the part
    before the test block takes most of it, but on the test block what it leaves is not noise, so it is not
    named, only said as "closest" with how much it removes."""
    rec = record(tmp_path, duration=30.0)
    counts = np.diff(rec.enc[:, 0])
    late = rec.t[1:] > 8.0
    counts[late] = np.round(1.3 * counts[late])
    enc = np.column_stack([rec.enc[0, 0] + np.concatenate([[0], np.cumsum(counts)]), rec.enc[:, 1]])
    d = diagnose(dataclasses.replace(rec, enc=enc.astype(rec.enc.dtype)), DEFAULT, ROOM, test_block=TEST_FRACTION)
    doc = json.loads(json.dumps(d.to_json()))
    assert d.verdict in ("unexplained", "partly explained") and d.located, d.summary()
    assert doc["closest"] is not None and set(doc["closest"]) == {"name", "removes_percent"}, d.summary()
    assert 0 < doc["closest"]["removes_percent"] <= 100
    assert doc["closest"]["name"].split("(")[0] not in [e["name"] for e in doc["effects"]]
    assert any(item["regime"] == "on the test block" for item in doc["unexplained"])
    assert "closest in the library: " in d.summary() and not d.model.effects


def test_an_effect_on_one_wheel_answers_for_its_own_and_the_bodys_channels():
    """A one-wheel effect is judged on its wheel's channels, the body's motion and the battery; the other
    wheel's own channels are that wheel's, reported beside it. An effect of both wheels or of the robot
    answers for every drive channel, a sensor's for its own."""
    from host_sim.diagnosis.block_verdict import family

    located = ["wheel_l", "count_l", "wheel_r", "count_r", "heading_rate", "turn", "vbat", "ir_2"]
    assert family("dry_friction", "left", located) == ["wheel_l", "count_l", "heading_rate", "turn", "vbat"]
    assert family("torque_constant", "right", located) == ["wheel_r", "count_r", "heading_rate", "turn", "vbat"]
    assert family("dry_friction", "both", located) == located[:-1]
    assert family("track_width", "both", located) == located[:-1]
    assert family("ir_gain", 2, located) == ["ir_2"]


def test_windows_that_touch_are_one_cluster():
    """A window's lead-in replays the end of the window before: back-to-back windows are one cluster of the
    intervals' sandwich, a window left out between them parts them."""
    from host_sim.diagnosis.fit import touching_runs
    from host_sim.diagnosis.windows import Windows

    windows = Windows(np.arange(12, 12 + 25 * 9, 25), 25, np.arange(9) % 3 == 2)
    train = np.flatnonzero(~windows.held_out)  # 0 1 3 4 6 7
    assert touching_runs(windows, np.repeat(train, 3)).tolist() == [0] * 6 + [1] * 6 + [2] * 6
    assert touching_runs(windows, np.array([8, 0, 1, 2])).tolist() == [1, 0, 0, 0]


@pytest.mark.slow
def test_the_intervals_hold_the_true_value_about_95_times_in_100(tmp_path):
    """Twin recordings of 20 s with a known dry friction on each wheel, 20 seeds: the window-clustered
    sandwich intervals of the two fitted values hold the truth in 85-99 % of the 40."""
    from host_sim.diagnosis.compare import compare_all, stratify
    from host_sim.diagnosis.fit import Candidate, fit_model

    true = [("dry_friction", "left", 0.001), ("dry_friction", "right", 0.0005)]
    robot = DEFAULT
    for name, site, value in true:
        robot = E.apply(robot, name, site, [value])
    held = 0
    for seed in range(20):
        fitted, _block = split_test_block(record(tmp_path, robot, 20.0, name=f"s{seed}.csv", seed=seed))
        first = compare_all(fitted, DEFAULT, ROOM)[0]
        stratify(first, fitted)
        objective = R.fit_objective(fitted, ROOM, first, clustered=True)  # as a diagnosis with a test block
        model = fit_model(objective, DEFAULT, [Candidate(n, s) for n, s, _v in true],
                          [E.absent_values(DEFAULT, n) for n, _s, _v in true])
        held += sum(lo <= v <= hi for (_n, _s, v), [(lo, hi)] in zip(true, model.ci95))
    assert 0.85 <= held / 40 <= 0.99


def test_the_reported_interval_adds_the_twins_model_error():
    """A named effect's reported interval is the fit's, each side widened in quadrature by MODEL_ERROR times
    the effect's size: its distance from absent, or a limit's own value where that is less; needed_share is
    the least share whose widening reaches the truth (the score MODEL_ERROR is the conformal quantile of)."""
    from host_sim.diagnosis.fit import Candidate, Model
    from host_sim.diagnosis.model_error import MODEL_ERROR, effect_size, needed_share, with_model_error

    assert MODEL_ERROR > 0
    assert effect_size("dry_friction", 0.002, DEFAULT) == 0.002  # absent: no extra friction
    assert effect_size("track_width", DEFAULT.half_axle + 0.001, DEFAULT) == pytest.approx(0.001)
    assert effect_size("current_limit", 0.2, DEFAULT.replace(current_limit=1.5)) == 0.2  # a limit: its value
    lo, hi = with_model_error("dry_friction", 0.002, (0.0019, 0.0022), DEFAULT, share=0.25)
    assert lo == pytest.approx(0.002 - math.hypot(0.0001, 0.0005))
    assert hi == pytest.approx(0.002 + math.hypot(0.0002, 0.0005))
    assert with_model_error("dry_friction", 0.002, (0.0019, 0.0022), DEFAULT, share=0.0) == (0.0019, 0.0022)
    assert with_model_error("dry_friction", 0.002, (0.0019, 0.0022), DEFAULT, share=5.0)[1] == \
        E.bounds("dry_friction", DEFAULT)[1][0]  # within the library's bounds
    share = needed_share("dry_friction", 0.002, (0.0019, 0.0022), 0.0014, DEFAULT)
    assert with_model_error("dry_friction", 0.002, (0.0019, 0.0022), DEFAULT, share=share)[0] == pytest.approx(0.0014)
    assert needed_share("dry_friction", 0.002, (0.0019, 0.0022), 0.0021, DEFAULT) == 0.0  # the fit's holds it

    chosen = Model([Candidate("dry_friction", "left")], [[0.002]], DEFAULT, 1.0, 1.0, 100)
    chosen.ci95 = [[(0.0019, 0.0022)]]
    entry = R._effect_entry(chosen, 0, [Model([], [], DEFAULT, 2.0, 2.0, 100), chosen], DEFAULT)
    reported = entry["params"]["dry_friction"]
    assert reported["ci95_fit"] == [0.0019, 0.0022]
    assert reported["ci95"] == list(with_model_error("dry_friction", 0.002, (0.0019, 0.0022), DEFAULT))
    assert reported["ci95"][0] < 0.0019 and reported["ci95"][1] > 0.0022


def test_without_the_opt_in_there_is_no_test_block(twin_run, monkeypatch):
    """diagnose without test_block compares and judges the whole recording on its held-out windows, as
    before the test block: no test figures, no keys of the rules in the JSON."""
    seen = []
    compare_all = R.compare_all
    monkeypatch.setattr(R, "compare_all", lambda rec, *a, **k: seen.append(rec.t[-1]) or compare_all(rec, *a, **k))
    d = diagnose(twin_run, DEFAULT, ROOM)
    assert seen and all(t_end == twin_run.t[-1] for t_end in seen)
    doc = d.to_json()
    assert d.verdict == "match" and not d.fit_test and set(doc["fit"]) == {"before", "after", "ceiling", "judged"}
    assert not {"changes", "test_judgements"} & set(doc) and doc["closest"] is None  # closest: always said


def test_a_match_the_fit_made_within_tolerance_is_judged_on_the_test_block_with_its_values(tmp_path):
    """A match whose twin is the build with effects fitted within the tolerance (report._name) is judged on
    the test block with that twin, not with the one the effects were sought from: a left wheel with twice
    its dry friction, matched by a twin that has it, stays a match there; the datasheet's twin would not."""
    from host_sim.diagnosis.block_verdict import judge_test_block
    from host_sim.diagnosis.fit import Candidate, Model

    value = [DEFAULT.coulomb_friction]
    robot = E.apply(DEFAULT, "dry_friction", "left", value)
    fitted, block = split_test_block(record(tmp_path, robot))

    def judged(twin):
        d = R.Diagnosis("run.csv", "match", [])
        d.model = Model([Candidate("dry_friction", "left")], [value], twin, 1.0, 1.0, 100)
        judge_test_block(d, block, DEFAULT, ROOM, [d.model], None, 1.0, None)
        return d

    assert judged(robot).verdict == "match"
    assert judged(DEFAULT).verdict == "unexplained"
