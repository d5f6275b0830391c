"""A replay started where the robot slid over the floor starts it sliding (host_sim.recordings.replay.sliding_rows).

The recordings are the twin's own identification manoeuvre on ice (a grip of 0.1: the wheels spin in
the steps, and the body runs on when they stop) and on the nominal floor; the tracker is the
simulator's truth.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from host_sim.physics import effects as E
from host_sim.robot.batch import SUBSTEPS
from host_sim.diagnosis.compare import compare
from host_sim.diagnosis.windows import FINE_SUBSTEPS, LEAD_ROWS, Windows, judge_slides, run_windows
from host_sim.physics.params import DEFAULT
from host_sim.recordings.recording import Recording
from host_sim.recordings.replay import replay, replay_batch, rolling_velocity, sliding_rows, tracked_velocity
from tests.test_diagnosis import ARENA, record_manoeuvre

ICE = E.apply(DEFAULT, "traction_limit", "both", [0.1])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("slides")
    return record_manoeuvre(tmp, DEFAULT, duration=20.0), record_manoeuvre(tmp, ICE, duration=20.0)


def test_the_tracker_tells_a_slide_from_rolling(runs):
    nominal, ice = runs
    assert not sliding_rows(nominal, DEFAULT)[0].any()
    slides, body = sliding_rows(ice, DEFAULT)
    assert 0.02 < slides.mean() < 0.5, slides.mean()
    gap = np.abs(body - rolling_velocity(ice, DEFAULT))
    assert gap[slides].max(axis=1).min() > 0.01 and np.median(gap[~slides][:, 0]) < 0.005
    np.testing.assert_array_equal(body, tracked_velocity(ice))


def _slide_row(rec, p):
    """A row in the middle of a slide, the body and the wheels' rims at least 5 cm/s apart."""
    slides, body = sliding_rows(rec, p)
    gap = np.abs(body[:, 0] - rolling_velocity(rec, p)[:, 0])
    rows = np.flatnonzero(slides & (gap > 0.05))
    rows = rows[(rows > 10) & (rows < len(rec) - 30)]
    assert rows.size, "the ice run never slid"
    return int(rows[len(rows) // 2])


def test_a_replay_from_a_slide_follows_the_slide(runs):
    """Started rolling at its wheels' speed, the twin would be a slide's speed off at once; started from the
    tracked body velocity it follows the recording, one robot or a batch, with or without an effect."""
    _nominal, ice = runs
    k = _slide_row(ice, ICE)
    rows = 5  # 0.2 s
    batch = replay_batch(ice, ICE, k, stop=k + rows, sensors=False)
    error = np.hypot(*(batch.pose[:, 0, :2] - ice.pose[k:k + rows, :2]).T)
    assert error.max() < 0.005, error  # 3 mm in 0.16 s; rolling from the wheels' speed, 14 mm
    # the diagnosis's windows alike, started on the window's first row
    windows = Windows(np.array([k]), rows, np.array([False]), lead=0)
    judge_slides(ice, windows, ICE, np.array([False]))
    assert windows.sliding is not None and windows.sliding[0]
    run = run_windows(ice, windows, ICE, ARENA)
    started = np.hypot(*(run.pose[0, 0, :, :2] - ice.pose[k:k + rows, :2]).T).max()
    assert started < 0.005
    # or LEAD_ROWS before it, rolling then: the twin slides into the window by itself and carries the slide on
    windows = Windows(np.array([k]), rows, np.array([False]))
    judge_slides(ice, windows, ICE, np.array([False]))
    assert windows.sliding is not None and not windows.sliding[0] and sliding_rows(ice, ICE)[0][k]
    run = run_windows(ice, windows, ICE, ARENA)
    assert np.hypot(*(run.pose[0, 0, :, :2] - ice.pose[k:k + rows, :2]).T).max() < 0.25 * started  # 0.1 mm, 2.7
    one = replay(ice, ICE, ARENA, k, k + rows)
    np.testing.assert_allclose(one.pose, batch.pose[:, 0], atol=1e-6)
    # a robot with an effect steps through a BatchSim of one: it too starts sliding
    dry = E.apply(ICE, "dry_friction", "left", [0.0002])
    np.testing.assert_allclose(replay(ice, dry, ARENA, k, k + rows).pose,
                               replay_batch(ice, dry, k, stop=k + rows, sensors=False).pose[:, 0], atol=1e-6)


def test_windows_step_finer_where_the_robot_slides(runs):
    """A slide spins the wheels up and down within milliseconds: its windows run FINE_SUBSTEPS a period."""
    nominal, ice = runs
    assert compare(nominal, DEFAULT, ARENA, locate=False).windows.substeps == SUBSTEPS
    assert compare(ice, DEFAULT, ARENA, locate=False).windows.substeps == FINE_SUBSTEPS > SUBSTEPS


def _lead_in_says_faster(rec, k: int) -> Recording:
    """rec with the counts of window row k's lead-in bent to say the wheels turn faster (a slope of 6/28
    counts a period over its seven rows), the rows the twin's start speeds are read from left alone."""
    bent = copy.deepcopy(rec)
    bent.enc[k - 4:k - 1] += np.array([-3, 0, 3])[:, None]
    return bent


def test_the_lead_in_counts_steer_the_twin_only_where_it_rolls(runs):
    """A wheel that spins on ice has its speed set by the floor within milliseconds, so the speed error the
    lead-in's counts show is not one it carries into the window: where the tracker sees a slide in the
    lead-in, the twin (nominal: it rolls) enters as the lead-in leaves it.  Where the robot rolls, the same
    counts set its speed."""
    _nominal, ice = runs
    slides = sliding_rows(ice, DEFAULT)[0]
    k_slide = _slide_row(ice, ICE)
    rolls = [k for k in range(40, len(ice) - 30) if not slides[k - LEAD_ROWS - 1:k + 6].any()]
    for k, steered in ((k_slide, False), (rolls[len(rolls) // 2], True)):
        windows = Windows(np.array([k]), 5, np.array([False]))
        judge_slides(ice, windows, DEFAULT, np.array([False]))
        assert windows.lead_slides is not None and bool(windows.lead_slides[0]) != steered
        run = run_windows(ice, windows, DEFAULT, None).enc
        bent = run_windows(_lead_in_says_faster(ice, k), windows, DEFAULT, None).enc
        assert np.allclose(np.diff(run, axis=2), np.diff(bent, axis=2), atol=1e-9) != steered, k
