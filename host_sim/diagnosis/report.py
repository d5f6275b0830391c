"""The verdict and its evidence: a terminal summary and a stable JSON document.

diagnose() runs the whole diagnosis: compare, locate, fit, then judge the fitted twin on the same held-out
windows (opt-in: on a test block, block_verdict).  Verdicts, refusals and the JSON keys: docs/diagnosis.md,
"Verdict" and "Output".
"""
from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from host_sim.physics import effects as E
from host_sim.diagnosis.tell_apart import tell_apart_all
from host_sim.diagnosis.compare import Comparison, compare_all, stratify
from host_sim.diagnosis.fit import Model, Objective, Refine, candidates_for, fit_totals, objective_channels, select
from host_sim.diagnosis.channels import (ACCUMULATED, IR, SENSOR_NAMES, WHEELS, drive_channel, drive_located,
                                        judged_windows, located_sensors, ring_comparable)
from host_sim.diagnosis.clipping import clipped
from host_sim.diagnosis.locate import (MIN_REGIME_S, Finding, Regimes, near_wall_seconds, noise_level, regimes, runs,
                                      total_noise)
from host_sim.diagnosis.ring import ring_law
from host_sim.diagnosis.model_error import with_model_error
from host_sim.diagnosis.odometry import Odometry, measure_odometry
from host_sim.diagnosis.odometry import per_count as odometry_per_count
from host_sim.diagnosis.windows import DEFAULT_SECONDS
from host_sim.diagnosis.testblock import TestBlockError, check_test_recording, split_test_block
from host_sim.diagnosis.block_verdict import (UNEXPLAINED_KEYS, judge_held_out, judge_match_held_out, judge_test_block,
                                              leave_what_odometry_locates, unexplained)
from host_sim.diagnosis.calibrate import (Calibration, Nuisance, calibrate, drive_nuisances, edge_binds,
                                          held_by_odometry, refit_jointly, sensor_nuisances)
from host_sim.diagnosis.tolerance import BANDS, Tolerance
from host_sim.diagnosis.phrasing import checked, sentence, spans_text
from host_sim.physics.params import DEFAULT, RobotParams
from host_sim.recordings.recording import Recording
from host_sim.recordings.replay import with_drive
from host_sim.physics.world import World

MIN_WINDOWS = 6  # 1 s windows: fewer and the held-out judgement rests on one or two windows
MIN_FREE_WINDOWS = MIN_WINDOWS  # of them away from the walls: the contact windows are judged apart
MIN_MOVING = 0.2  # share of periods in which a wheel turns, on the robot or the twin: less says little of the physics


class DiagnosisError(ValueError):
    """The recording cannot be diagnosed; the message says why and what would help."""


@dataclass
class Diagnosis:
    recording: str
    verdict: str
    comparisons: list[Comparison]
    located: list[dict[str, Any]] = field(default_factory=list)
    effects: list[dict[str, Any]] = field(default_factory=list)
    fit_before: dict[str, float] = field(default_factory=dict)
    fit_after: dict[str, float] = field(default_factory=dict)
    fit_ceiling: dict[str, float] = field(default_factory=dict)  # per wheel: a twin right but for the rounding
    fit_judged: list[list[float]] = field(default_factory=list)  # [t0, t1] of the windows the wheels are judged on
    unexplained: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    recording_checks: list[dict[str, Any]] = field(default_factory=list)  # checks.Note's: mended, never fitted
    fit_test: dict[str, Any] = field(default_factory=dict)  # on the test block: before, after, ceiling, judged
    closest: dict[str, Any] | None = None  # an effect that removes part of a mismatch it does not explain
    changes: list[dict[str, Any]] = field(default_factory=list)  # effects whose halves differ: not named
    test_judgements: list[dict[str, Any]] = field(default_factory=list)  # verdict.Judgement per channel judged
    model: Model | None = None  # the fitted twin, when effects were tried
    calibration: Calibration | None = None  # the twin calibrated within the datasheet's tolerance
    odometry: Odometry | None = None  # each wheel's distance per count against the tracker (odometry.py)
    located_datasheet: list[dict[str, Any]] = field(default_factory=list)  # what the datasheet twin showed
    after: Comparison | None = None  # the fitted twin judged on the same windows
    after_long: Comparison | None = None  # ... and on the longest ones (pictures)
    # the build calibrated within the tolerance where it still located something, and its comparisons: what is
    # unexplained where no effect earns its place (_name)
    within: tuple[Calibration, list[Comparison]] | None = field(default=None, repr=False)
    # the twin whose fit is the "after" where it is neither the model's nor the twin before's: the build
    # within the tolerance, where no effect explains what it leaves (_unexplained_by_any)
    after_params: RobotParams | None = field(default=None, repr=False)
    # each named effect's entry, label and the model that chose it: its rivals are told apart once the verdict
    # has settled which effects stay named (_tell_apart_named)
    apart: list[tuple[dict[str, Any], str, Model]] = field(default_factory=list, repr=False)

    def to_json(self) -> dict[str, Any]:
        doc = {"recording": self.recording, "verdict": self.verdict, "located": self.located,
               "effects": self.effects, "fit": {"before": _finite(self.fit_before), "after": _finite(self.fit_after),
                                                "ceiling": _finite(self.fit_ceiling), "judged": self.fit_judged},
               "unexplained": self.unexplained, "notes": self.notes, "recording_checks": self.recording_checks}
        if self.calibration is not None:
            doc["calibration"] = {"values": self.calibration.to_json(), "located_before": self.located_datasheet}
        doc["closest"] = self.closest
        if self.odometry is not None:
            doc["odometry"] = self.odometry.to_json()
        if self.fit_test:  # judged on a test block (diagnose's test_block): its figures and rules' findings
            doc["fit"]["test"] = {k: (_finite(v) if isinstance(v, dict) else v) for k, v in self.fit_test.items()}
            doc |= {"changes": self.changes, "test_judgements": self.test_judgements}
        return doc

    def summary(self) -> str:
        lines = [f"{self.recording}: {self.verdict}"]
        lines += [f"  {checked(item)}" for item in self.recording_checks]
        lines += [f"  note: {n}" for n in self.notes]
        for item in self.located:
            lines.append(f"  - {item['words']} (fit {item['fit_before']:.0f} %)")
        for e in self.effects:
            where = f" ({e['wheel']} wheel)" if "wheel" in e else (f" (sensor {e['sensor']})" if "sensor" in e else "")
            values = ", ".join(f"{k} = {v['value']:.4g} {v['unit']} [{v['ci95'][0]:.4g}, {v['ci95'][1]:.4g}]"
                               for k, v in e["params"].items())
            alt = e["evidence"]["explains_equally_well"]
            lines.append(f"  effect: {e['name']}{where}: {values}" + (f"; as well: {', '.join(alt)}" if alt else ""))
            lines += [f"    {text}" for text in e["evidence"].get("told_apart_by", [])]
        for item in self.unexplained:
            lines.append(f"  unexplained: {item['words']}")
        if self.closest is not None:
            lines.append(f"  closest in the library: {self.closest['name']}, which removes "
                         f"{self.closest['removes_percent']:.0f} % of it" + (" (on the test block; not named)"
                                                                              if self.fit_test else " (not named)"))
        shown = [k for k in self.fit_before if not k.startswith("amb_")]
        after = bool(self.effects) or self.within is not None and self.verdict != "match"  # another twin's fit
        lines.append("  held-out fit % per channel (1 s windows), before" + (" -> after" if after else "") + ": "
                     + ", ".join(f"{k} {self.fit_before[k]:.0f}" + (f" -> {self.fit_after.get(k, float('nan')):.0f}"
                                                                    if after else "") for k in shown))
        test = self.fit_test
        if test.get("before"):
            lines.append(f"  test block ({test['from_s']:.0f}-{test['to_s']:.0f} s, seen by no fit nor rule), fit % "
                         f"before -> after: " + ", ".join(
                             f"{k} {v:.0f} -> {test['after'].get(k, float('nan')):.0f}"
                             for k, v in test["before"].items() if not k.startswith("amb_")))
        wheels = [k for k in WHEELS if k in self.fit_ceiling]
        if wheels:
            lines.append("  the wheels' ceiling (a twin right but for the encoders' rounding): "
                         + ", ".join(f"{k} {self.fit_ceiling[k]:.0f}" for k in wheels))
        return "\n".join(lines)


def _finite(d: dict[str, float]) -> dict[str, float | None]:
    return {k: (round(v, 2) if math.isfinite(v) else None) for k, v in d.items()}


# What each kind of motion, away from the walls, lets the diagnosis judge (with less than MIN_REGIME_S of it,
# poorly).
REGIME_EFFECTS = (("turning", (0, 2), "turned", "track width, turning resistance and the centre of mass"),
                  ("direction", (1,), "drove backwards", "backlash and the wheels' asymmetries in reverse"),
                  ("acceleration", (1, 2), "accelerated or braked", "mass, inertia and actuator delay"))


def excitation_notes(rec: Recording, first: Comparison, params: RobotParams, world: World | None) -> list[str]:
    """A note on the kinds of motion the recording holds too little of, away from the walls ([] if none)."""
    reg = regimes(rec, first.windows, params, world)
    free = ~first.contact
    did, effects = [], []
    for name, values, doing, judged in REGIME_EFFECTS:
        seconds = float(np.isin(reg.labels[name][0][free], values).sum()) * rec.sample_period
        if seconds < MIN_REGIME_S:
            did.append(f"{doing} for {seconds:.1f} s")
            effects.append(judged)
    notes = [f"away from the walls the robot {'; '.join(did)} only, so these are poorly judged: "
             f"{'; '.join(effects)} (the identification manoeuvre has all of these: twinbot serial PORT --excite)"
             ] if did else []
    return notes + sensor_excitation_notes(rec, reg, world)


def sensor_excitation_notes(rec: Recording, reg: Regimes, world: World | None) -> list[str]:
    """A note on the IR sensors that faced a wall within 12 cm of the rim for less than MIN_REGIME_S in all
    (they are judged at a wall too: channels.judged_windows): a sensor's gain, alignment and latency show only
    in its readings of a near wall, so a `match` says little of them
    (tests/test_diagnosis.py::test_a_sensor_that_seldom_faced_a_wall_is_said_to_be_poorly_judged)."""
    if world is None or world.n_walls == 0:
        return []  # no walls: the IR ring is not judged at all, and check_data says so
    seldom = [f"{SENSOR_NAMES[k]} for {seconds:.1f} s" for k, seconds in enumerate(near_wall_seconds(rec, reg))
              if f"wall_{k}" in reg.labels and seconds < MIN_REGIME_S]
    if not seldom:
        return []
    return [f"a wall came within 12 cm of {', '.join(seldom)} only, so these sensors' gain, alignment and "
            f"latency are poorly judged (a run that brings each sensor near a wall for {MIN_REGIME_S:.0f} s "
            f"judges them)"]


def windows_notes(first: Comparison) -> list[str]:
    """Notes on the windows left out over a late or lost row (windows.late_rows) and those judged apart at a
    wall."""
    notes, left_out = [], first.windows.left_out
    if left_out:
        notes.append(f"{left_out} of {len(first.windows) + left_out} windows hold a late or lost row: left out, as "
                     f"the command a lost row carried is not recorded and a twin holding the one before would "
                     f"diverge for a while")
    if int(first.contact.sum()):
        notes.append(f"{int(first.contact.sum())} of {len(first.contact)} windows touch a wall: judged apart "
                     f"(channel 'contact')")
    return notes


def check_data(rec: Recording, world: World | None, params: RobotParams | None = None) -> list[str]:
    """Refuse what is too short to diagnose; return notes on what this recording cannot show."""
    period = rec.sample_period
    if len(rec) * period < MIN_WINDOWS * DEFAULT_SECONDS[0]:
        raise DiagnosisError(f"the recording lasts {len(rec) * period:.1f} s: too short to diagnose "
                             f"(at least {MIN_WINDOWS * DEFAULT_SECONDS[0]:.0f} s; 60-90 s is better)")
    notes = []
    if rec.bench:
        notes.append("recorded on a bench (wheels off the floor, the body held): the twin holds its body; traction, "
                     "the caster, contact and the body's motion are not judged")
    elif rec.pose is None:
        notes.append("no tracker pose: judged on the encoders and the battery only; effects on the body's motion "
                     "(track width vs wheel radius, slip) and on the IR sensors cannot be told apart without it")
    elif world is None or world.n_walls == 0:
        notes.append("no walls known: the IR sensors are not judged")
    elif not ring_comparable(rec, params or DEFAULT):
        ring = len((params or DEFAULT).ir_bearings)
        notes.append(f"the recording's {rec.n_ir} IR sensors{'' if rec.ambient_recorded else ' (no ambient readings)'}"
                     f" are not the twin's ring of {ring} pairs (ir_bearings): the IR sensors are not judged")
    if not rec.battery_recorded:
        notes.append("no battery voltage recorded: the battery is not judged")
    if params is not None and params.drive_kind == "wheel_speed":
        # The loop's output is not recorded: the same load at other volts leaves the wheels at their set-points
        # (tests/test_import.py::test_the_diagnosis_says_what_it_cannot_judge).
        notes.append("the commands are wheel-speed set-points, which the robot's own speed loop holds: a load on the "
                     "drive (friction, a motor's resistance or torque constant, a drag, a slope) shows only while the "
                     "loop settles, so a match says little of it (a recording of the loop's output as the commands, "
                     "a duty or voltage drive, judges it)")
    return notes


def without_gapped_pose(rec: Recording) -> tuple[Recording, list[str]]:
    """A recording whose tracker lost the robot in some rows, judged without the tracker (its windows
    start from recorded states, which a row without a pose does not give), and the note that says so."""
    if rec.pose is None or rec.pose_rows.all():
        return rec, []
    missing = int((~rec.pose_rows).sum())
    return dataclasses.replace(rec, pose=None), [
        f"the tracker pose is missing in {missing} of {len(rec)} rows: judged without the tracker"]


class TooLittleData(DiagnosisError):
    """The recording shows too little to call the twin a match; `shortfall` says what is missing.  A
    mismatch located all the same is still diagnosed (diagnose)."""

    def __init__(self, shortfall: str, consequence: str) -> None:
        super().__init__(f"{shortfall}: {consequence}")
        self.shortfall = shortfall


def check_excitation(rec: Recording, first: Comparison) -> None:
    """Raise TooLittleData if the wheels hardly turn, unless the commands would turn the twin's.

    The excitation is in the commands: a robot that stands still away from the walls while its motors are
    driven (a seized wheel, say) is a mismatch to diagnose, not missing data.  Held against a wall (or
    without a tracker, which cannot tell a wall from a seized wheel) it is too little to judge.
    """
    wheels = [first.channel(name) for name in WHEELS]
    robot = np.any([np.abs(c.y) >= 1 for c in wheels], axis=0)
    twin = np.any([np.abs(c.y_hat[:, 0]) >= 0.5 for c in wheels], axis=0)  # rounds to a tick
    free = ~first.contact[:, None] if rec.pose is not None else np.zeros((len(first.contact), 1), bool)
    if (robot | (twin & free)).mean() >= MIN_MOVING:
        return
    why = ""
    held = twin & ~robot & ~free
    if held.mean() >= MIN_MOVING:
        why = (f"; the twin, driven by the same commands, turns them in {100 * (robot | twin).mean():.1f} %, but "
               + (f"the robot touches a wall in {int(first.contact.sum())} of {len(first.contact)} windows"
                  if rec.pose is not None else "without a tracker a wall cannot be told from a seized wheel"))
    raise TooLittleData(f"the wheels turn in only {100 * robot.mean():.1f} % of the periods (at least "
                        f"{100 * MIN_MOVING:.0f} % needed{why})", "too little excitation to diagnose (run the "
                        "identification manoeuvre: twinbot serial PORT --excite)")


def check_judgeable(rec: Recording, first: Comparison) -> None:
    """Raise TooLittleData on a recording the comparison shows too little of to call it a match: wheels
    that hardly turn (check_excitation), or a robot pressed against walls nearly the whole time."""
    check_excitation(rec, first)
    if int((~first.contact).sum()) < MIN_FREE_WINDOWS:
        raise TooLittleData(f"the robot touches a wall in {int(first.contact.sum())} of {len(first.contact)} windows",
                            f"pressed against walls nearly the whole time, too little else to judge (at least "
                            f"{MIN_FREE_WINDOWS} windows of {first.seconds:g} s away from the walls)")


def diagnose(rec: Recording, params: RobotParams, world: World | None, *,
             seconds: tuple[float, ...] = DEFAULT_SECONDS, progress: Callable[[str], None] | None = None,
             workers: int = 1, test_block: float | Recording | None = None,
             bands: dict[str, float] | None = None) -> Diagnosis:
    """Compare, locate and fit, the verdict judged on the held-out windows.  With test_block (opt-in), all
    that runs on all but a test block, which the verdict is then judged on (judge_test_block): the last
    test_block share of rec's 1 s windows (a float, e.g. testblock.TEST_FRACTION), or a second recording
    of the same robot and world.
    workers > 1: each step's screening and its shortlisted fits run in that many processes (the same
    figures, sooner: fit.select).  bands: the datasheet's tolerance (tolerance.BANDS by default), within
    which the twin is calibrated before anything is named."""
    params = with_drive(rec, params)  # the recording's commands are for its own drive (docs/recordings.md)
    tol = Tolerance(params, dict(BANDS if bands is None else bands))
    rec, gap_notes = without_gapped_pose(rec)
    if isinstance(test_block, Recording):
        test_block = without_gapped_pose(test_block)[0]
    if test_block is None:
        result = _diagnose_fitted(rec, tol, world, seconds, progress, workers)[0]
        result.notes[:0] = gap_notes
        _report_clips(result, rec, params)
        _report_odometry(result, rec, params, world, tol)
        judge_match_held_out(result, rec.t)
        _tell_apart_named(result)
        return result
    try:
        if isinstance(test_block, Recording):
            check_test_recording(test_block, seconds[0])
            fitted, block = rec, test_block
        else:
            fitted, block = split_test_block(rec, float(test_block), seconds[0])
    except TestBlockError as exc:
        raise DiagnosisError(str(exc)) from None
    result, chain, objective, base = _diagnose_fitted(fitted, tol, world, seconds, progress, workers, test_block=True)
    result.notes[:0] = gap_notes
    result.recording = str(rec.path or "recording")
    if isinstance(test_block, Recording):  # a second recording: its own checks' notes
        result.recording_checks += [n.to_json() | {"test": True} for n in block.notes]
    judge_test_block(result, block, base, world, chain, objective, seconds[0], progress)
    for part in ([rec, test_block] if isinstance(test_block, Recording) else [rec]):
        _report_clips(result, part, params)
    _report_odometry(result, rec, params, world, tol)
    _tell_apart_named(result)
    return result


def _report_clips(result: Diagnosis, rec: Recording, params: RobotParams) -> None:
    """Clipped sensors (clipping.py) are a mismatch the library does not hold: located and unexplained, one
    item per level the readings stop at (sensors that share an ADC's reference share it), so the verdict is
    neither a match nor wholly explained
    (tests/test_clipping.py::test_clipped_readings_are_unexplained_and_fit_no_sensor_gain)."""
    clips = clipped(rec, params)
    for level in sorted({c.level for c in clips}):
        at = [c for c in clips if c.level == level]
        found = runs(np.logical_or.reduce([c.rows for c in at]), rec.t)
        names = ", ".join(SENSOR_NAMES[c.sensor] for c in at)
        item = {"channel": IR[at[0].sensor], "sensors": [c.sensor for c in at], "regime": f"at {level} counts",
                "spans": [list(s) for s in found],
                "fit_before": min(result.fit_before.get(IR[c.sensor], math.nan) for c in at),
                "words": f"{'sensor' if len(at) == 1 else 'sensors'} {names}: the readings stop at {level} counts, "
                         f"below the ADC's {params.adc_max} ({sum(int(c.rows.sum()) for c in at)} readings there): "
                         f"clipped (the ADC's reference or the amplifier), which the twin does not hold; those "
                         f"readings are not judged, {spans_text(found)}"}
        _file_unexplained(result, item, ("channel", "sensors", "regime", "spans", "words"))


def _file_unexplained(result: Diagnosis, item: dict[str, Any], keys: tuple[str, ...]) -> None:
    """A located mismatch the library does not hold: filed as located and (its keys) unexplained, so the
    verdict is neither a match nor wholly explained
    (tests/test_odometry.py::test_a_wheel_that_goes_too_far_per_count_is_no_match)."""
    result.located.append(item)
    result.unexplained.append({k: item[k] for k in keys})
    result.verdict = {"match": "unexplained", "explained": "partly explained"}.get(result.verdict, result.verdict)


ODOMETRY_EFFECTS = ("wheel_radius", "encoder_scale")  # the library's effects on a wheel's distance per count


def _report_odometry(result: Diagnosis, rec: Recording, params: RobotParams, world: World | None,
                     tol: Tolerance) -> None:
    """A wheel whose distance per count, against the tracker (odometry.py), lies beyond its radius's tolerance
    of what the named effects make it is a mismatch whatever the dynamics say: located and unexplained, so
    the verdict is neither a match nor wholly explained.  A wheel radius or encoder scale named that the
    odometry contradicts on a wheel, beyond the band of what it makes that wheel over its 95 % interval, is
    no longer named: kinematics measure it directly
    (tests/test_odometry.py::test_a_wheel_that_goes_too_far_per_count_is_no_match).  Any other effect named on
    such a wheel leaves that mismatch located: at most closest (block_verdict.leave_what_odometry_locates)."""
    odo = result.odometry = measure_odometry(rec, params, world)
    if odo is None:
        return
    band = tol.bands.get("wheel_radius", 0.0)
    named = [e for e in result.effects if e["name"] in ODOMETRY_EFFECTS]
    beyond = odo.beyond(band, _implied_per_count(named, params))  # none where the named effects agree
    if named and beyond:
        result.effects = [e for e in result.effects if e not in named]
        result.notes.append("not named, as the odometry contradicts it on a wheel: " + ", ".join(
            f"{e['name']} ({e.get('wheel', 'both')})" for e in named))
        if not result.effects and result.verdict in ("explained", "partly explained"):
            result.verdict = "unexplained"
        beyond = odo.beyond(band)
    for w in beyond:
        side = ("left", "right")[w]
        d = odo.per_count[w]
        lo, hi = odo.interval(w)
        item = {"channel": f"odometry_{side[0]}", "regime": "per encoder count", "spans": [list(odo.span)],
                "fit_before": result.fit_before.get(f"count_{side[0]}", math.nan), "value": d,
                "words": f"the {side} wheel goes {100 * abs(d):.1f} % {'less far' if d < 0 else 'farther'} per "
                         f"encoder count than the datasheet's ({100 * lo:.1f}-{100 * hi:.1f} %), beyond its radius's "
                         f"{100 * band:.1f} % tolerance "
                         f"(the encoders against the tracker, {odo.windows} windows clear of the walls): a wheel "
                         f"of another radius, or an encoder of another count per turn"}
        _file_unexplained(result, item, UNEXPLAINED_KEYS)
    leave_what_odometry_locates(result, beyond)


def _implied_per_count(named: list[dict[str, Any]], datasheet: RobotParams) -> tuple[tuple[float, float], ...]:
    """Each wheel's distance per count, against the datasheet's (relative), that the named effects give over
    their reported 95 % intervals: (lo, hi) per wheel ((0, 0) with none named)."""
    base = odometry_per_count(datasheet)
    made = []
    for ends in itertools.product(*[itertools.product(*[prm.get("ci95") or (prm["value"], prm["value"])
                                                        for prm in e["params"].values()]) for e in named]):
        p = datasheet
        for e, values in zip(named, ends):
            p = E.apply(p, e["name"], e.get("wheel", "both"), list(values))
        made.append([m / b - 1.0 for m, b in zip(odometry_per_count(p), base)])
    return tuple((min(m[w] for m in made), max(m[w] for m in made)) for w in (0, 1))


def _ring_and_notes(rec: Recording, tol: Tolerance, world: World | None, seconds: float
                    ) -> tuple[Tolerance, list[str]]:
    """(tol, its IR law scaled to the ring's own where the ring judges it: what every pair shares is the law's, not
    a pair's fault (ring.py; tests/test_ring.py); the data's notes (check_data), and the ring's)."""
    ring = ring_law(rec, tol.datasheet, world, seconds)
    if ring is not None:
        tol = Tolerance(ring.params, tol.bands)
    return tol, check_data(rec, world, tol.datasheet) + ([ring.words()] if ring is not None else [])


def _diagnose_fitted(rec: Recording, tol: Tolerance, world: World | None, seconds: tuple[float, ...],
                     progress: Callable[[str], None] | None, workers: int, test_block: bool = False
                     ) -> tuple[Diagnosis, list[Model], Objective | None, RobotParams]:
    """The diagnosis on rec (with a test block: the part fitted): (its result, the chain of models, the
    objective, the twin the effects were fitted to: calibrated within tolerance); test_block: a test block
    follows, whose rules then judge what is named (block_verdict.judge_test_block)."""
    tol, notes = _ring_and_notes(rec, tol, world, seconds[0])
    params = tol.datasheet
    say = progress or (lambda _text: None)
    say("comparing the twin with the recording")
    comparisons = compare_all(rec, params, world, seconds)
    first = comparisons[0]
    stratify(first, rec)  # before any figure is taken: the held-out windows hold a share of what was located
    result = Diagnosis(str(rec.path or "recording"), "match", comparisons, [_located(first, f) for f in first.findings],
                       fit_before=dict(first.fit), fit_ceiling=dict(first.ceiling), fit_judged=judged_spans(rec, first),
                       notes=notes, recording_checks=[n.to_json() for n in rec.notes])
    little_data = False
    try:
        check_judgeable(rec, first)
    except TooLittleData as thin:
        little_data = True
        # Too little to call it a match: that nothing is located there is no evidence.  A mismatch located
        # all the same is (a few seconds of driving can show a weak motor), and is diagnosed, said to rest on
        # little data.  Tested: tests/test_diagnosis.py::
        # test_too_little_to_call_a_match_still_shows_a_mismatch_and_names_it_only_if_it_explains_it
        if not result.located:
            raise
        result.notes.append(f"little data: {thin.shortfall}; a mismatch is located all the same, and what "
                            f"follows rests on what there is")
    result.notes += windows_notes(first)
    result.notes += excitation_notes(rec, first, params, world)
    if not result.located:
        result.fit_after = dict(first.fit)
        return result, [], None, params
    judge = _judge(rec, world, seconds, first.windows.held_out)
    base, first = _within_tolerance(result, rec, world, first, tol, judge, say)
    if not result.located:
        return result, [], None, base
    objective = fit_objective(rec, world, first)
    objective.tolerance = tol
    chain = _fit_with_the_build(result, objective, base, first, tol, say, workers, judge)
    final = result.model = chain[-1]
    say("judging the fitted twin")
    afters = judge(final.params)
    after = result.after = afters[0]
    result.after_long = afters[-1]
    result.fit_after = dict(after.fit)
    remaining = [_located(after, f) for f in after.findings]
    if little_data and final.effects and remaining:
        # With little data, effects that leave the mismatch located are no evidence of their names, nor is a
        # build fitted on a few windows: the twin the effects were sought from is reported (the same test).
        result.notes.append(f"with so little data, what the library fits best "
                            f"({', '.join(c.label() for c in final.effects)}) leaves the mismatch located: "
                            f"no name is given")
        final = result.model = chain[0]
        result.after, result.after_long, result.fit_after, result.within = first, comparisons[-1], dict(first.fit), None
    _name(result, final, chain, remaining, tol, (first, after), test_block)
    return result, chain, objective, base


def _name(result: Diagnosis, final: Model, chain: list[Model], remaining: list[dict[str, Any]], tol: Tolerance,
          compared: tuple[Comparison, Comparison], test_block: bool) -> None:
    """The effects named and the verdict: none the robot as built may hold (_as_built), and without a test
    block only those that explain what they answer for (block_verdict.judge_held_out); compared: the twin
    the effects were sought from and the fitted one, on the same held-out windows."""
    built = [_as_built(final, i, tol) for i in range(len(final.effects))]
    result.effects = [_effect_entry(final, i, chain, tol.datasheet, result.apart) for i, b in enumerate(built) if not b]
    for why, words in (("within", "fitted within the datasheet's tolerance, the robot as built and not named"),
                       ("reaches", "fitted beyond the datasheet's tolerance, but with the twin's model error its 95 % "
                                   "interval reaches it: the robot as built may hold it, not named")):
        if why in built:
            result.notes.append(f"{words}: " + ", ".join(c.label() for c, b in zip(final.effects, built) if b == why))
    result.unexplained = unexplained(remaining)
    if not result.effects and final.effects and not remaining:
        # Every effect fitted lies within its band (or its interval reaches it) and, with the build, leaves nothing
        # located: the robot as built explains the recording, a match
        # (tests/test_tolerance.py::test_a_build_the_effects_fit_within_tolerance_is_a_match).
        result.verdict, result.located_datasheet, result.located = "match", result.located, []
        result.notes.append("with the build and these values, each within the datasheet's tolerance or within the "
                            "twin's model error of it, nothing is located: the robot as built")
    elif not result.effects:
        result.verdict = "unexplained"
        if not final.effects:  # else what is left is what the build with its values within tolerance leaves
            _unexplained_by_any(result)
    else:
        result.verdict = "explained" if not remaining else "partly explained"
        if not test_block:  # with one, the block's rules judge what is named (judge_test_block)
            judge_held_out(result, *compared, chain)


def _unexplained_by_any(result: Diagnosis) -> None:
    """No effect earned its place: what is unexplained is what the twin nearest the robot leaves, the build
    calibrated within the tolerance where it still locates something (its fit the one reported, its build the
    one written), else what the twin the effects were sought from locates.  The datasheet's twin would count
    the part of the mismatch the tolerance holds as unexplained
    (tests/test_tolerance.py::test_what_no_effect_explains_is_what_the_build_within_tolerance_leaves)."""
    if result.within is None:
        result.unexplained = unexplained(result.located)
        return
    cal, compared = result.within
    after = compared[0]
    result.unexplained = unexplained([_located(after, f) for f in after.findings])
    result.calibration, result.model, result.after_params = cal, None, cal.params
    result.after, result.after_long, result.fit_after = after, compared[-1], dict(after.fit)
    result.notes.append("no effect of the library explains the mismatch beyond the datasheet's tolerance; what is "
                        "unexplained is what the build calibrated within it leaves")


def _within_tolerance(result: Diagnosis, rec: Recording, world: World | None, first: Comparison, tol: Tolerance,
                      judge: Callable[[RobotParams], list[Comparison]], say: Callable[[str], None]
                      ) -> tuple[RobotParams, Comparison]:
    """Calibrate the twin within the datasheet's tolerance (calibrate.py) and locate again: where nothing is
    left (and no edge holds back a fault), a match, the robot as built, and (the calibrated twin, its
    comparison); else (the twin the effects are sought from, each group that does not explain its own
    channels back at the datasheet's values, and its comparison)
    (tests/test_tolerance.py::test_a_robot_within_its_tolerance_is_a_match)."""
    located = [f.channel for f in first.findings]
    drive = drive_nuisances(tol, "vbat" in [c.name for c in first.channels], rec.bench) if drive_located(located) else []
    sensors = sensor_nuisances(tol, located_sensors(located))
    if not drive and not sensors:
        return tol.datasheet, first
    say("calibrating the twin within the datasheet's tolerance")
    cal, binding = Calibration(tol.datasheet), []
    odo = measure_odometry(rec, tol.datasheet, world)
    for group in (drive, sensors):  # the sensors read the recorded track: apart, they run no physics
        if group:
            part, objective = _calibrate_group(rec, world, first, tol, judge, cal.params, group,
                                               held_by_odometry(odo, group, tol))
            if part.at_edge() and edge_binds(objective, cal.params, tol, part, located):
                binding += part.at_edge()
            cal = Calibration(part.params, cal.nuisances + part.nuisances, cal.values + part.values,
                              cal.bands + part.bands, cal.held + part.held)
    result.notes.append(f"calibrated within the datasheet's tolerance: {cal.words()}")
    if binding:
        # The data takes the build beyond its tolerance: a fault, which the build took up in part (so that
        # nothing may be left located) (tests/test_tolerance.py::test_a_fault_the_build_can_almost_take_up_is_still_named).
        result.notes.append("held at the tolerance's edge (" + ", ".join(n.label() for n in binding) + "): the "
                            "mismatch lies beyond the tolerance")
    calibrated = judge(cal.params)
    left = [f.channel for f in calibrated[0].findings]
    if not binding and not left:
        result.calibration, result.located_datasheet, result.located = cal, result.located, []
        result.after, result.fit_after = calibrated[0], dict(calibrated[0].fit)
        return cal.params, calibrated[0]
    if left:
        result.within = cal, calibrated
    # Where a group's edge binds, or its channels are still located, its effects are sought from the
    # datasheet's values: a build fitted without the fault took up part of it and would bias each effect
    # fitted on top; the build is fitted beside each effect chosen instead (_fit_with_the_build).  A group
    # its calibration explains keeps it.
    reset = {n for n in cal.nuisances if n in binding or any(_answers(n, c) for c in left)}
    # The drive's mechanics are one group; the battery is read directly, so it goes back only for its own
    # channel (tests/test_tolerance.py::test_the_battery_keeps_its_calibration_when_the_drive_goes_back).
    reset |= {n for n in cal.nuisances if _mechanical(n) and any(_mechanical(m) for m in reset)}
    cal = cal.at_datasheet(tol, reset)
    result.calibration = cal
    start = judge(cal.params)[0]
    located_datasheet, result.located = result.located, [_located(start, f) for f in start.findings]
    if not result.located:
        # The groups back at the datasheet leave nothing located: a match with those values, and the report
        # says which (tests/test_tolerance.py::test_a_match_with_the_build_back_at_the_datasheet_says_so).
        result.located_datasheet = located_datasheet
        result.after, result.fit_after = start, dict(start.fit)
        result.notes.append(f"the calibrated build left a little located; back at the datasheet's values "
                            f"({cal.words()}) nothing is located")
    return cal.params, start


def _calibrate_group(rec: Recording, world: World | None, first: Comparison, tol: Tolerance,
                     judge: Callable[[RobotParams], list[Comparison]], params: RobotParams, group: list[Nuisance],
                     held: dict[Nuisance, float]) -> tuple[Calibration, Objective]:
    """(a group's calibration, its objective): fitted weighed by the noise the datasheet twin leaves, then
    weighed by the noise the calibrated twin leaves and fitted once more from there.  The datasheet twin's
    spread counts the mismatch being calibrated away as noise, and so weighs a turn or a count a few per
    cent off too little for the locator's test of it
    (tests/test_tolerance.py::test_the_build_is_weighed_by_the_noise_it_leaves)."""
    objective = _group_objective(rec, world, first, group)
    part = calibrate(objective, params, tol, group, held=held)
    objective.sigma = objective_sigma(judge(part.params)[0], objective.names, objective.totals)
    return calibrate(objective, params, tol, group, start=part.values, held=held), objective


def _answers(n: Nuisance, channel: str) -> bool:
    """A nuisance's group answers for the channel: the battery's for its reading, the drive's mechanics for
    the drive's other channels, a sensor's gain for its own."""
    if n.index is not None:
        return channel in (f"ir_{n.index}", f"amb_{n.index}")
    return channel == "vbat" if n.quantity == "battery_voltage" else drive_channel(channel) and channel != "vbat"


def _mechanical(n: Nuisance) -> bool:
    """One of the drive's mechanics (a wheel's, a motor's, the track), not the battery or a sensor."""
    return n.index is None and n.quantity != "battery_voltage"


def _group_objective(rec: Recording, world: World | None, first: Comparison, group: list) -> Objective:
    """The objective a group of nuisances is calibrated on: the drive's channels for the drive's, the
    sensors' own for their gains, weighed as a fit weighs them (objective_sigma)."""
    located = [f.channel for f in first.findings]
    sensors = {n.index for n in group if n.index is not None}
    wanted = objective_channels(located, [c.name for c in first.channels])
    names = [n for n in wanted if (int(n.split("_")[1]) in sensors if n.startswith(("ir_", "amb_")) else not sensors)]
    totals = fit_totals(located) if not sensors else ()
    return Objective(rec, first.windows, world, names, objective_sigma(first, names, totals), first.contact,
                     first.unjudged, totals)


def _judge(rec: Recording, world: World | None, seconds: tuple[float, ...], held_out: np.ndarray
           ) -> Callable[[RobotParams], list[Comparison]]:
    """compare_all of a twin against the recording on the first comparison's held-out windows, the last
    twin's kept: the check before each further effect (fit.select's still_located) and the verdict then judge
    the same twin once."""
    last: dict[str, list[Comparison]] = {}  # by the twin's parameters' repr

    def judge(twin: RobotParams) -> list[Comparison]:
        key = repr(twin)
        if key not in last:
            last.clear()
            last[key] = compare_all(rec, twin, world, seconds, held_out=held_out)
        return last[key]

    return judge


def _relocate(judge: Callable[[RobotParams], list[Comparison]]) -> Callable[[Model, Objective], list[str]]:
    """fit.select's still_located: what the locator still finds with a fitted twin, the weights of the next
    step (objective_sigma) set from the same comparison, the noise that twin leaves."""

    def still_located(model: Model, obj: Objective) -> list[str]:
        cmp = judge(model.params)[0]
        obj.sigma = objective_sigma(cmp, obj.names, obj.totals)
        return [f.channel for f in cmp.findings]

    return still_located


def judged_spans(rec: Recording, cmp: Comparison) -> list[list[float]]:
    """[t0, t1] (s, the first and last rows' times) of each held-out window the wheels' fit % is judged on:
    away from the walls (channels.judged_windows), in time order."""
    w = cmp.windows
    judged = w.held_out & judged_windows(WHEELS[0], cmp.contact)
    return [[float(rec.t[k]), float(rec.t[k + w.rows - 1])] for k in w.start[judged]]


def _located(cmp: Comparison, f: Finding) -> dict[str, Any]:
    item = {"channel": f.channel, "regime": f.regime, "spans": [list(s) for s in f.spans],
            "fit_before": cmp.fit.get(f.channel, float("nan")), "words": sentence(f),
            "mean_residual": f.mean, "z": f.z, "whiteness_p": cmp.whiteness.get(f.channel),
            "input_lag_periods": cmp.lag.get(f.channel, (None,))[0]}
    if f.rms is not None:  # a wheel that scatters without a bias (locate.scatter_finding)
        item["rms_residual"] = f.rms
    if f.lag is not None:  # a wheel that runs behind (or ahead of) the twin (locate.lag_finding)
        item["lag_s"] = f.lag
    return item


def _fit(objective: Objective, params: RobotParams, first: Comparison, say: Callable[[str], None], workers: int = 1,
         still_located: Callable[[Model, Objective], list[str]] | None = None, refine: Refine | None = None
         ) -> list[Model]:
    located = [f.channel for f in first.findings]
    offered = candidates_for(located, params.drive_kind, objective.rec.bench)
    return select(objective, params, offered, progress=say, located=located, workers=workers,
                  still_located=still_located, refine=refine)


def _fit_with_the_build(result: Diagnosis, objective: Objective, base: RobotParams, first: Comparison,
                        tol: Tolerance, say: Callable[[str], None], workers: int,
                        judge: Callable[[RobotParams], list[Comparison]]) -> list[Model]:
    """The effects chosen (fit.select), each chosen one refitted with the robot's build within its tolerance
    (calibrate.refit_jointly) before the next is sought; result.calibration ends as the build fitted last."""
    build = result.calibration
    if build is None or not build.nuisances:
        return _fit(objective, base, first, say, workers, still_located=_relocate(judge))
    builds: dict[int, tuple[Model, Calibration]] = {}  # by id of each refitted model (kept alive): its build

    def refine(model: Model) -> tuple[Model, RobotParams]:
        joint, fitted = refit_jointly(objective, tol, build, model)
        builds[id(joint)] = (joint, fitted)
        return joint, fitted.params

    chain = _fit(objective, base, first, say, workers, still_located=_relocate(judge), refine=refine)
    if chain[-1].effects and id(chain[-1]) not in builds:  # backward elimination refitted the chain
        say("fitting the effects and the robot's build together")
        chain[-1] = refine(chain[-1])[0]
    result.calibration = builds[id(chain[-1])][1] if chain[-1].effects else build
    return chain


def fit_objective(rec: Recording, world: World | None, first: Comparison, clustered: bool = True) -> Objective:
    """What a fit minimises: the located channels and their family, each on the windows it is judged on
    (the drive's away from the walls); clustered: its fits' intervals are the window-clustered sandwich
    (always in a diagnosis; the Jacobian's, widened for correlation, otherwise)."""
    located = [f.channel for f in first.findings]
    names = objective_channels(located, [c.name for c in first.channels])
    totals = fit_totals(located)
    objective = Objective(rec, first.windows, world, names, objective_sigma(first, names, totals), first.contact,
                          first.unjudged, totals)
    objective.clustered_intervals = clustered
    return objective


def objective_sigma(cmp: Comparison, names: list[str], totals: tuple[str, ...]) -> dict[str, float]:
    """The weights of a fit's residuals: each channel's noise level about the twin compared (locate.noise_level),
    and each window total's (fit.Objective) by how far the totals stray from a proportion (locate.total_noise).
    Taken from the nominal twin for the first effect, and again from the twin fitted so far for each further
    one: a first effect's mismatch spreads the totals about their proportion, and weighed by that spread a
    second effect's turn or travel counts for little
    (tests/test_diagnosis.py::test_a_blind_pair_is_named_in_full_on_the_reference_plant)."""
    sigma = {c.name: noise_level(c, c.residual()[judged_windows(c.name, cmp.contact)])
             for c in cmp.channels if c.name in names}
    sigma |= {ACCUMULATED[c.name]: total_noise(c, judged_windows(c.name, cmp.contact)) for c in cmp.channels
              if c.name in names and c.name in totals}
    return sigma


def _as_built(model: Model, i: int, tol: Tolerance) -> str:
    """Why the model's effect i is the robot as built: "within" (its values lie within their bands), "reaches"
    (its 95 % intervals with the twin's model error, model_error.py, reach them), or "" (a fault)."""
    name, values = model.effects[i].name, model.values[i]
    if tol.within(name, values):
        return "within"
    reaches = bool(model.ci95) and tol.reaches(name, _reported_intervals(model, i, tol.datasheet))
    return "reaches" if reaches else ""


def _reported_intervals(model: Model, i: int, datasheet: RobotParams) -> list[tuple[float, float]]:
    """Effect i's 95 % intervals as reported: the fit's, widened for the twin's model error (model_error.py)."""
    name = model.effects[i].name
    return [with_model_error(name, v, ci, datasheet) for v, ci in zip(model.values[i], model.ci95[i])]


def _effect_entry(model: Model, i: int, chain: list[Model], datasheet: RobotParams,
                  later: list[tuple[dict[str, Any], str, Model]] | None = None) -> dict[str, Any]:
    """A named effect: its values with the 95 % interval that holds the robot's value (the fit's, widened for
    the twin's model error: model_error.py; the fit's alone is `ci95_fit`), and the evidence for it.  With
    `later`, the sentences telling it apart from its rivals are left to _tell_apart_named (each runs the
    manoeuvre twice, wasted on an effect the verdict then leaves as the closest)."""
    cand = model.effects[i]
    effect = E.LIBRARY[cand.name]
    entry: dict[str, Any] = {"name": cand.name}
    if effect.kind == "drive":
        entry["wheel"] = cand.site
    elif effect.kind == "sensor":
        entry["sensor"] = cand.site
    reported = _reported_intervals(model, i, datasheet) if model.ci95 else None
    entry["params"] = {prm.name: {"value": model.values[i][j], "unit": prm.unit,
                                  "ci95": list(reported[j]) if reported else None,
                                  "ci95_fit": list(model.ci95[i][j]) if model.ci95 else None,
                                  "field": prm.field.format(w="l" if cand.site == "left" else "r")
                                  if effect.kind == "drive" and cand.site != "both" else prm.field}
                       for j, prm in enumerate(effect.params)}
    step = chain[i + 1] if i + 1 < len(chain) else model
    before = chain[i]
    entry["evidence"] = {"doc": effect.doc, "p_value": step.p_value,
                         "held_out_cost_before": before.cost_test, "held_out_cost_after": step.cost_test,
                         "held_out_gain_located": step.located_gain,
                         "explains_equally_well": step.alternatives,
                         "told_apart_by": [] if later is not None else _apart_sentences(cand.label(), step)}
    if later is not None:
        later.append((entry, cand.label(), step))
    return entry


def _apart_sentences(label: str, step: Model) -> list[str]:
    return tell_apart_all((label, step.params), [(r.effects[-1].label(), r.params) for r in step.rivals])


def _tell_apart_named(result: Diagnosis) -> None:
    """Each effect still named: the data that would tell it apart from each rival that explains as well
    (tests/test_diagnosis_apart.py::test_only_the_effects_still_named_are_told_apart)."""
    for entry, label, step in result.apart:
        if any(entry is kept for kept in result.effects):
            entry["evidence"]["told_apart_by"] = _apart_sentences(label, step)
    result.apart = []
