"""What would tell two effects apart: the manoeuvre run on both fitted twins (host_sim/diagnosis/tell_apart.py)."""
from __future__ import annotations

import numpy as np
import pytest

from host_sim.diagnosis import tell_apart
from host_sim.diagnosis.fit import Candidate, Model
from host_sim.diagnosis.report import _effect_entry
from host_sim.loops.excitation import SEGMENTS
from host_sim.physics.params import DEFAULT

RADIUS = DEFAULT.replace(wheel_radius_delta_l=0.0008)
FRICTION = DEFAULT.replace(coulomb_friction_delta_l=0.0008)


@pytest.fixture(scope="module")
def runs():
    return {name: tell_apart.run_manoeuvre(p) for name, p in
            (("nominal", DEFAULT), ("radius", RADIUS), ("friction", FRICTION))}


def test_the_manoeuvre_run_covers_every_segment(runs):
    run = runs["nominal"]
    assert set(run.segment) == {name for name, _d, _f in SEGMENTS}
    assert run.cmd.shape == (len(run.segment), 2) and run.speed.max() > 0.1


def test_identical_twins_are_not_separated(runs):
    rows = tell_apart.separation(runs["nominal"], runs["nominal"])
    assert max(level for _s, level, _w in rows) == 0.0


def test_a_drive_effect_is_separated_where_its_physics_shows(runs):
    # Extra dry friction on one wheel costs the same torque at every speed: the speed loop must push harder on
    # that wheel whenever it turns, most of all where it keeps starting and stopping.
    seg, level, words = tell_apart.separation(runs["nominal"], runs["friction"])[0]
    assert level > tell_apart.SEPARATION_MIN and "current references" in words
    by_segment = {s: lv for s, lv, _w in tell_apart.separation(runs["nominal"], runs["friction"])}
    assert by_segment["reversals"] > by_segment["creep"]


def test_twins_run_together_run_as_alone():
    # run_manoeuvres steps every twin in one batch, each with its own firmware: each must run as it would alone
    # (its commands the same, its motion to rounding), or a rival's sentence would carry another twin's figures.
    twins = [FRICTION, DEFAULT.replace(actuator_delay=0.02), RADIUS]
    together = tell_apart.run_manoeuvres(twins, cycles=0.2)
    for p, run in zip(twins, together):
        alone = tell_apart.run_manoeuvres([p], cycles=0.2)[0]
        assert (run.segment == alone.segment).all() and np.array_equal(run.cmd, alone.cmd)
        np.testing.assert_allclose(run.speed, alone.speed, rtol=0, atol=1e-9)
        np.testing.assert_allclose(run.yaw_rate, alone.yaw_rate, rtol=0, atol=1e-9)
    assert not np.array_equal(together[0].cmd, together[1].cmd)  # the twins differ: each kept its own


def test_the_sentence_names_the_segment_and_the_command():
    text = tell_apart.tell_apart(("wheel_radius(left)", RADIUS), ("dry_friction(left)", FRICTION))
    assert text.startswith("wheel_radius(left) and dry_friction(left) explain it equally well")
    assert any(f"manoeuvre's {name} would tell them apart" in text for name, _d, _f in SEGMENTS)
    assert tell_apart.COMMAND in text


def test_ir_pairs_are_told_apart_by_their_physics():
    text = tell_apart.tell_apart(("ir_offset(3)", DEFAULT), ("ambient_leakage(3)", DEFAULT))
    assert "ambient light" in text and "leakage scales with the ambient" in text


def test_the_report_carries_a_sentence_per_rival():
    chosen = Model([Candidate("wheel_radius", "left")], [[0.0008]], RADIUS, 1.0, 1.0, 100)
    rival = Model([Candidate("dry_friction", "left")], [[0.0008]], FRICTION, 1.0, 1.01, 100)
    chosen.rivals, chosen.alternatives = [rival], ["dry_friction(left)"]
    nominal = Model([], [], DEFAULT, 2.0, 2.0, 100)
    entry = _effect_entry(chosen, 0, [nominal, chosen], DEFAULT)
    assert entry["evidence"]["explains_equally_well"] == ["dry_friction(left)"]
    (sentence,) = entry["evidence"]["told_apart_by"]
    assert sentence.startswith("wheel_radius(left) and dry_friction(left)")


def test_only_the_effects_still_named_are_told_apart():
    """The sentences (each a pair of manoeuvre runs for a drive effect) are made once the verdict has settled
    which effects stay named: an effect it leaves as the closest gets none, a kept one its sentence."""
    from host_sim.diagnosis.report import Diagnosis, _tell_apart_named

    def chosen(effect, site, rival_effect):
        model = Model([Candidate(effect, site)], [[20.0]], DEFAULT, 1.0, 1.0, 100)
        model.rivals = [Model([Candidate(rival_effect, site)], [[0.2]], DEFAULT, 1.0, 1.01, 100)]
        model.alternatives = [f"{rival_effect}({site})"]
        return model

    result = Diagnosis("rec", "explained", [])
    nominal = Model([], [], DEFAULT, 2.0, 2.0, 100)
    kept, dropped = (_effect_entry(m, 0, [nominal, m], DEFAULT, result.apart)
                     for m in (chosen("ir_offset", 3, "ambient_leakage"), chosen("ir_offset", 5, "ambient_leakage")))
    assert kept["evidence"]["told_apart_by"] == [] and len(result.apart) == 2  # left for later
    result.effects = [kept]  # the verdict kept one, left the other as the closest
    _tell_apart_named(result)
    (sentence,) = kept["evidence"]["told_apart_by"]
    assert sentence.startswith("ir_offset(3) and ambient_leakage(3)")
    assert dropped["evidence"]["told_apart_by"] == [] and result.apart == []
