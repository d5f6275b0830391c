"""The verdict on the test block: a twin is a match, or an effect is named, only if what it leaves there is
noise (verdict.judge_channels); an effect that removes part of a mismatch is "closest", one whose two
halves differ "changes during the recording".  docs/diagnosis.md, "Verdict".
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from host_sim.diagnosis.channels import ACCUMULATED, IR, AMBIENT, WHEELS, drive_channel, sensor_channel
from host_sim.diagnosis.compare import Comparison, compare
from host_sim.diagnosis.fit import MIN_LOCATED_GAIN, Candidate, Model, Objective, fit_apart
from host_sim.diagnosis.phrasing import drift_words, test_block_words
from host_sim.diagnosis.verdict import changed, drifts, judge_channels, removed_percent, step_window
from host_sim.diagnosis.windows import make_windows
from host_sim.physics import effects as E
from host_sim.physics.params import RobotParams
from host_sim.physics.world import World
from host_sim.recordings.recording import Recording


def judge_test_block(result: Any, block: Recording, params: RobotParams, world: World | None, chain: list[Model],
                     objective: Objective | None, seconds: float, progress: Callable[[str], None] | None) -> None:
    """Set result's test-block figures and judge its verdict there (result: a report.Diagnosis)."""
    say = progress or (lambda _text: None)
    say("judging on the test block")
    every = np.ones(len(make_windows(block, seconds)), dtype=bool)  # the test block: every window judged
    before = compare(block, params, world, seconds, locate=False, held_out=every)
    twin = _after_twin(result)
    after = compare(block, twin, world, seconds, locate=False, held_out=every) if twin is not None else before
    t = block.t
    result.fit_test = {"from_s": float(t[before.windows.start[0]]),
                       "to_s": float(t[before.windows.start[-1] + before.windows.rows - 1]),
                       "windows": len(every), "before": dict(before.fit), "after": dict(after.fit),
                       "ceiling": dict(after.ceiling)}
    if result.verdict == "match":
        _judge_match(result, block, after)
    elif result.effects:
        _judge_named(result, block, before, after, chain, objective, params, say)


def _after_twin(result: Any) -> RobotParams | None:
    """The twin whose fit is the "after": the fitted model's with effects, else the build calibrated within the
    tolerance where no effect explains what it leaves (report._unexplained_by_any), so that the test block's
    after is the same twin's as the held-out windows' (tests/test_tolerance.py::
    test_the_test_blocks_after_is_the_build_that_leaves_what_no_effect_explains); None: the twin before,
    also on a match, which is the twin before's (the build back at the datasheet's values)."""
    model = result.model
    if model is not None and model.effects:
        return model.params
    return result.after_params


def judged_names(cmp: Comparison) -> list[str]:
    """Every channel the locator judges, and the window totals of those that have them."""
    names = [c.name for c in cmp.channels if c.locate]
    return names + [ACCUMULATED[n] for n in names if n in ACCUMULATED]


def _span(result: Any) -> list[list[float]]:
    return [[result.fit_test["from_s"], result.fit_test["to_s"]]]


def _judge_match(result: Any, block: Recording, twin: Comparison) -> None:
    """A match needs its twin (the build, with any effect fitted within the tolerance: report._name) near its
    ceiling on the test block and no trend in time there, on every channel (whiteness is not asked of it:
    nothing is named) (tests/test_verdict.py::
    test_a_match_the_fit_made_within_tolerance_is_judged_on_the_test_block_with_its_values)."""
    judged = judge_channels(twin, block.t, judged_names(twin))
    result.test_judgements = [j.to_json() for j in judged.values()]
    failing = [j for j in judged.values() if not (j.near and j.steady)]
    if failing:
        result.verdict = "unexplained"
        result.unexplained = [{"channel": j.channel, "regime": "on the test block", "spans": _span(result),
                               "words": test_block_words(j, result.fit_test)} for j in failing]


def judge_match_held_out(result: Any, t: np.ndarray) -> None:
    """Without a test block, a match needs no drift on the held-out windows either: a drive channel whose
    windows' mean residual moves with time by the smallest bias the locator names (verdict.drifts) is
    unexplained, whatever the twin (the build, fitted within tolerance, or the datasheet's) makes of it on
    average (tests/test_verdict.py::test_a_match_that_drifts_over_the_recording_is_unexplained).  Not the IR
    sensors': they read the recorded track, so their residual maps the IR law's error over the walls the
    route passed, and a route that changes over the run trends without any drift
    (tests/test_verdict.py::test_a_match_is_not_held_to_drift_on_its_sensors)."""
    if result.verdict != "match":
        return
    cmp = result.after if result.after is not None else result.comparisons[0]
    span = [float(t[cmp.windows.start[0]]), float(t[cmp.windows.start[-1] + cmp.windows.rows - 1])]
    items = [{"channel": j.channel, "regime": "over the recording", "spans": [span],
              "fit_before": result.fit_before.get(j.channel, float("nan")), "words": drift_words(j, change, span)}
             for j, change in drifts(cmp, t, [c for c in judged_names(cmp) if drive_channel(c)])]
    if items:
        result.located += items
        result.unexplained += unexplained(items)
        result.verdict = "unexplained"


UNEXPLAINED_KEYS = ("channel", "regime", "spans", "words")  # what a located item says, unexplained


def unexplained(items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The located items as unexplained ones: where, in which regime, when, and the words."""
    return [{k: item[k] for k in UNEXPLAINED_KEYS} for item in items]


OTHER_WHEEL = {"left": (WHEELS[1], ACCUMULATED[WHEELS[1]]), "right": (WHEELS[0], ACCUMULATED[WHEELS[0]])}


def family(effect: str, site: Any, located: list[str]) -> list[str]:
    """The located channels an effect answers for: the drive's for a drive or robot effect, but for the other
    wheel's own where it acts on one wheel (a mismatch left there is that wheel's, reported beside it:
    tests/test_verdict.py::test_an_effect_on_one_wheel_answers_for_its_own_and_the_bodys_channels), sensor k's
    for its own, every sensor's for the ring's."""
    kind = E.LIBRARY[effect].kind
    if kind == "sensor":
        return [c for c in located if c in (IR[int(site)], AMBIENT[int(site)])]
    if kind == "ring":
        return [c for c in located if sensor_channel(c)]
    other = OTHER_WHEEL.get(str(site), ())
    return [c for c in located if drive_channel(c) and c not in other]


def _judge_named(result: Any, block: Recording, before: Comparison, after: Comparison, chain: list[Model],
                 objective: Objective | None, params: RobotParams, say: Callable[[str], None]) -> None:
    """Each named effect stays named only if every located channel it answers for is left noise on the test
    block (near, white, steady); else it is at most "closest".  Those left are fitted on the recording's
    two halves apart (_changes)."""
    located = list(dict.fromkeys(item["channel"] for item in result.located))
    judged = judge_channels(after, block.t, located)
    result.test_judgements = [j.to_json() for j in judged.values()]
    kept, closest = _keep_explaining(result, before, after, located,
                                     lambda own: all(c in judged and judged[c].explains for c in own))
    failing = [j for j in judged.values() if not j.explains]
    result.unexplained += [{"channel": j.channel, "regime": "on the test block", "spans": _span(result),
                            "words": test_block_words(j, result.fit_test)} for j in failing]
    result.effects, result.closest = kept, closest
    if kept and objective is not None and result.model is not None:
        say("fitting the named effects on each half of the recording")
        _changes(result, objective, params, located)
    _settle(result, chain)


def judge_held_out(result: Any, before: Comparison, after: Comparison, chain: list[Model]) -> None:
    """Without a test block, the same rule on the held-out windows: an effect is named only where the fitted
    twin leaves none of the located channels it answers for located; else it is at most "closest"
    (tests/test_tolerance.py::test_an_effect_that_leaves_its_channels_located_is_not_named)."""
    left = {item["channel"] for item in result.unexplained}
    # a channel the fit made a mismatch of counts as one it leaves
    located = list(dict.fromkeys([item["channel"] for item in result.located] + sorted(left)))
    result.effects, result.closest = _keep_explaining(result, before, after, located,
                                                      lambda own: not left.intersection(own))
    _settle(result, chain)
    if not result.effects:  # nothing named: everything located is left unexplained
        result.unexplained = unexplained(result.located)


def leave_what_odometry_locates(result: Any, wheels: list[int]) -> None:
    """The same rule for a wheel whose distance per count the odometry puts beyond its tolerance, which no
    named effect accounts for (report._report_odometry): an effect that answers for that wheel was fitted on
    a twin that goes the datasheet's distance per count there, and leaves the odometry's mismatch located, so
    it is at most "closest" (its located gain) (tests/test_odometry.py::
    test_an_effect_that_leaves_the_odometrys_mismatch_on_its_wheel_is_not_named)."""
    kept, closest = [], result.closest
    for entry in result.effects:
        if any(family(entry["name"], site_of(entry), [WHEELS[w]]) for w in wheels):
            closest = nearer(closest, entry, 100.0 * entry.get("evidence", {}).get("held_out_gain_located", 0.0))
        else:
            kept.append(entry)
    if len(kept) < len(result.effects):
        sides = " and ".join(("left", "right")[w] for w in wheels)
        result.notes.append(f"not named, as the twin fitted with it leaves the {sides} wheel's distance per count "
                            f"beyond its tolerance: " + ", ".join(e["name"] + f" ({site_of(e)})"
                                                                  for e in result.effects if e not in kept))
        result.effects, result.closest = kept, closest
        _settle(result, [])
        if not kept:  # nothing named: everything located is left unexplained
            result.unexplained = unexplained(result.located)


def _keep_explaining(result: Any, before: Comparison, after: Comparison, located: list[str],
                     explains: Callable[[list[str]], bool]) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
    """(the effects that explain the located channels they answer for, the closest of the others: the one
    that removes the most of its channels' residual, if any removes some)."""
    kept, closest = [], None
    for entry in result.effects:
        own = family(entry["name"], site_of(entry), located)
        if own and explains(own):
            kept.append(entry)
            continue
        closest = nearer(closest, entry, removed_percent(before, after, own) if own else 0.0)
    return kept, closest


def site_of(entry: dict[str, Any]) -> Any:
    """A named effect's site: its wheel, its sensor, or "both"."""
    return entry.get("wheel", entry.get("sensor", "both"))


def nearer(closest: dict[str, Any] | None, entry: dict[str, Any], removes: float) -> dict[str, Any] | None:
    """The closest effect of the two: `closest`, or the entry not named that removes `removes` % of the
    mismatch, where it removes more (and some)."""
    if removes <= 0 or (closest is not None and removes <= closest["removes_percent"]):
        return closest
    return {"name": Candidate(entry["name"], site_of(entry)).label(), "removes_percent": round(float(removes), 1)}


def _changes(result: Any, objective: Objective, params: RobotParams, located: list[str]) -> None:
    """Fit the model on the first and the second half of the part fitted apart; an effect whose parameter
    differs beyond the two intervals (verdict.changed) is not named as a constant: it "changes during the
    recording", near the window where a step fits the located channels best (verdict.step_window)."""
    model: Model = result.model
    start = objective.windows.start
    first_half = start < np.median(start)
    halves = [fit_apart(objective, params, model, keep) for keep in (first_half, ~first_half)]
    cmp = result.after  # the fitted twin on the part fitted: where a step fits its residuals best
    at = step_window(cmp, located) if cmp is not None else 0
    t_at = float(objective.rec.t[cmp.windows.start[at]]) if cmp is not None else float("nan")
    kept = []
    for entry in result.effects:
        i = next(k for k, c in enumerate(model.effects) if _same(c, entry))
        a, b = halves[0], halves[1]
        if not changed(a.values[i], b.values[i], a.ci95[i], b.ci95[i]):
            kept.append(entry)
            continue
        change = {"name": entry["name"], "first_half": a.values[i], "second_half": b.values[i], "at_s": t_at}
        result.changes.append(change)
        result.unexplained.append({"channel": entry["name"], "regime": "during the recording", "spans": [[t_at, t_at]],
                                   "words": f"{entry['name']} changes during the recording: "
                                            f"{_values(a.values[i])} in the first half, {_values(b.values[i])} in "
                                            f"the second, a step fits best at {t_at:.0f} s"})
    result.effects = kept


def _values(values: list[float]) -> str:
    return ", ".join(f"{v:.4g}" for v in values)


def _same(cand: Any, entry: dict[str, Any]) -> bool:
    site = entry.get("wheel", entry.get("sensor", "both"))
    return cand.name == entry["name"] and cand.site == site


def _settle(result: Any, chain: list[Model]) -> None:
    """The verdict from what is named and what is left: explained, partly explained (something named, or a
    closest effect that removes MIN_LOCATED_GAIN of the mismatch), unexplained."""
    if result.effects:
        result.verdict = "partly explained" if result.unexplained else "explained"
        return
    removes = result.closest["removes_percent"] if result.closest else 0.0
    result.verdict = "partly explained" if removes >= 100 * MIN_LOCATED_GAIN else "unexplained"
    if chain:
        result.model = chain[0]  # nothing named: the parameters written are the nominal twin's
