"""The IR ring's own law (host_sim/diagnosis/ring.py): what every pair shares is the law's, and a pair is judged
against the others.  The recordings are the twin's own, its law scaled as a robot's sensors or its walls may
scale it."""
from __future__ import annotations

import dataclasses

import pytest

from host_sim.diagnosis import diagnose
from host_sim.diagnosis import ring as R
from host_sim.physics.params import DEFAULT
from tests.test_diagnosis import ROOM, record

BRIGHT = 1.2  # every pair reads 20 % above the datasheet's law
RING = 1.1  # as the reference plant's IR curve reads about 8 % above the twin's law


def ring_with(tmp_path, law, pair6, name="run.csv"):
    """The twin's recording with its law scaled by `law` and pair 6's own gain `pair6`."""
    scale = tuple(pair6 if k == 6 else 1.0 for k in range(8))
    return record(tmp_path, DEFAULT.replace(ir_gain=DEFAULT.ir_gain * law, ir_gain_scale=scale), name=name)


def test_the_ring_reads_as_much_above_the_law_as_its_walls_and_a_weak_pair_is_judged_against_the_others(tmp_path,
                                                                                                      monkeypatch):
    rec = ring_with(tmp_path, BRIGHT, 0.7)
    ring = R.ring_law(rec, DEFAULT, ROOM, 1.0)
    assert ring is not None and 6 in ring.pairs and len(ring.pairs) >= R.MIN_PAIRS
    assert ring.factor == pytest.approx(BRIGHT, rel=0.01)  # the median holds beside the weak pair
    assert ring.gains[6] / ring.factor == pytest.approx(0.7, rel=0.02)
    assert ring.params.ir_gain == pytest.approx(DEFAULT.ir_gain * ring.factor)
    assert R.ring_law(rec, DEFAULT, None, 1.0) is None  # no walls to judge a pair by
    assert R.ring_law(dataclasses.replace(rec, ambient_recorded=False), DEFAULT, ROOM, 1.0) is None  # nor a reading
    # fewer pairs at a wall than MIN_PAIRS: the law stands
    monkeypatch.setattr(R, "MIN_PAIRS", len(ring.pairs) + 1)
    assert R.ring_law(rec, DEFAULT, ROOM, 1.0) is None


def test_a_pair_within_its_band_on_a_ring_brighter_than_the_law_is_a_match(tmp_path, monkeypatch):
    """Pair 6 12 % above the others is within the pairs' 15 % band, but 23 % above the datasheet's law: judged
    against the law it was named a fault."""
    rec = ring_with(tmp_path, RING, 1.12)
    d = diagnose(rec, DEFAULT, ROOM)
    assert d.verdict == "match" and not d.effects
    assert any(n.startswith("the IR ring reads +10.") for n in d.notes)
    monkeypatch.setattr("host_sim.diagnosis.report.ring_law", lambda *_a: None)
    d = diagnose(rec, DEFAULT, ROOM)
    assert d.verdict == "explained" and d.to_json()["effects"][0]["sensor"] == 6


def test_a_weak_pair_on_a_ring_brighter_than_the_law_is_measured_against_the_others(tmp_path, monkeypatch):
    rec = ring_with(tmp_path, RING, 0.72)
    for ring in (True, False):
        if not ring:
            monkeypatch.setattr("host_sim.diagnosis.report.ring_law", lambda *_a: None)
        (gain,) = diagnose(rec, DEFAULT, ROOM).to_json()["effects"]
        value, (lo, hi) = gain["params"]["ir_gain"]["value"], gain["params"]["ir_gain"]["ci95"]
        assert gain["sensor"] == 6
        # against the law, the pair reads 10 % too much and its interval misses it
        assert (value == pytest.approx(0.72, rel=0.02) and lo < 0.72 < hi) if ring else (value > 0.72 * 1.08 and lo > 0.72)
