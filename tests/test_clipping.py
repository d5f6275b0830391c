"""Clipped IR readings (host_sim/diagnosis/clipping.py, docs/diagnosis.md "Clipped readings"): found from the
readings alone, never fitted as a sensor's optics, and reported as located and unexplained."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from host_sim.diagnosis import diagnose
from host_sim.diagnosis.clipping import clipped
from host_sim.physics.params import DEFAULT
from tests.test_diagnosis import ROOM, record

LEVEL = 300  # counts: under the walls' readings on most sensors of the nominal run


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return record(tmp_path_factory.mktemp("clipping"))


def with_on(rec, on):
    return dataclasses.replace(rec, ir_on=np.asarray(on, dtype=rec.ir_on.dtype))


def test_readings_piled_below_full_scale_are_a_clip_noisy_or_full_scale_ones_are_not(run):
    assert clipped(run, DEFAULT) == []  # the twin's own noisy readings: their top values are rare
    clips = clipped(with_on(run, np.minimum(run.ir_on, LEVEL)), DEFAULT)
    reached = [k for k in range(run.n_ir) if (run.ir_on[:, k] > LEVEL + 10).sum() >= 5]
    assert len(reached) >= 3 and [c.sensor for c in clips] == reached
    for c in clips:
        assert c.level == LEVEL and np.array_equal(c.rows, run.ir_on[:, c.sensor] >= LEVEL)
    # the ADC's own full scale is the twin's saturation, not a clip
    ten_bits = dataclasses.replace(DEFAULT, adc_bits=10)
    assert clipped(with_on(run, np.minimum(run.ir_on, ten_bits.adc_max)), ten_bits) == []
    # a sensor that reads one value throughout (dead, or a log's empty IR columns) is not clipped
    assert clipped(with_on(run, np.zeros_like(run.ir_on)), DEFAULT) == []
    # without noise a steady reading is no clip in one visit, and is one in two
    quiet = dataclasses.replace(DEFAULT, ir_noise=0.0)
    on = np.full_like(run.ir_on, 100)
    on[50:70, 0] = 400
    assert clipped(with_on(run, on), quiet) == []
    on[150:170, 0] = 400
    assert [(c.sensor, c.level) for c in clipped(with_on(run, on), quiet)] == [(0, 400)]


def test_clipped_readings_are_unexplained_and_fit_no_sensor_gain(run):
    """The nominal twin's run with its readings clipped: one located, unexplained item naming the sensors
    and the level, no reflected-light mismatch located around it, and nothing fitted (a gain or an
    offset would otherwise take the clip up)."""
    d = diagnose(with_on(run, np.minimum(run.ir_on, LEVEL)), DEFAULT, ROOM)
    assert d.verdict == "unexplained" and not d.effects and d.closest is None
    [item] = d.located
    assert item["regime"] == f"at {LEVEL} counts" and len(item["sensors"]) >= 3
    assert f"stop at {LEVEL} counts" in item["words"] and "clipped" in item["words"]
    assert [u["sensors"] for u in d.unexplained] == [item["sensors"]]
    assert d.to_json()["unexplained"][0]["channel"].startswith("ir_")
