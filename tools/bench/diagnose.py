"""`twinbot bench diagnose`: diagnosis proven blind on recordings from the reference plant.

Generates a suite of cases (tools/reference_plant/cases.py), diagnoses each recording knowing only its
sidecar, runs the SINDy baseline beside it, and scores both against the answer keys
(diagnose_scoring.py).  docs/proving-ground.md, "The blind suite".
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any

from host_sim.diagnosis.model_error import MODEL_ERROR
from host_sim.physics.params import DRIVES
from tools.bench.report import print_targets

# The targets are the diagnosis issue's, set before any suite scored them (docs/proving-ground.md).
TARGET_NAMED = 0.90  # share of concealed (excited, in-library) effects named with the right side
TARGET_PARAMS = 0.90  # share of the rightly named effects whose parameter is within scoring.PARAM_TOLERANCE
TARGET_WHEEL_FIT = 90.0  # held-out fit % after, on both wheels ...
TARGET_WHEEL_SHARE = 0.95  # ... in this share of the cases (controls and in-library effects)
TARGET_FALSE_ALARMS = 0.05  # share of controls whose verdict is not "match"
TARGET_UNLISTED = 0.95  # share of out-of-library effects called unexplained / partly explained, rightly located
TARGET_COVERAGE = (0.85, 0.99)  # share of the named effects' 95 % intervals that hold the true value
CONFORMAL_LEVEL = 0.95  # the model error's share is the conformal quantile at this level (model_error.MODEL_ERROR)
TARGET_SECONDS = 10.0  # CPU seconds per 90 s recording (median), all of a diagnosis's processes
TARGET_SECONDS_MAX = 60.0  # ... and the slowest
REFERENCE_SECONDS = 90.0

DESCRIPTION = """\
  1. Generate: --cases blind cases on the reference plant, the MuJoCo robot
     (tools/reference_plant/cases.make_case, seeds --seed, --seed + 1, ...):
     one random effect in its realistic range or none (an effect-free
     control; with --effects K, K effects at once in each in-library case),
     a random built-in world and start, and the firmware driving (its
     exploration, or the identification manoeuvre), --duration seconds each.
     Each case's robot is drawn from the datasheet (tools/reference_plant/
     robot_draw.py).  --split tuning (the default) draws seeds 0..9999 and
     the kinds decision rules may be set on; --split final, seeds 100000 +
     --seed on, adds the held-back kinds (cable_drag, encoder_drift,
     weakening_motor).  --drive gives every case's robot that drive (an
     H-bridge for voltage, duty and wheel_speed; current by default) and
     draws only the effects of that drive.  The suite holds at least one
     control and one effect outside the library: if the seeds drew none,
     the last cases are swapped for the next seeds that do.  Recordings go
     to DIR/recordings, answer keys apart to DIR/answer_keys.
  2. Diagnose blind: host_sim.diagnosis.diagnose on each recording, with the
     robot and the world of its sidecar, nothing else (the worker is given
     the recording's path only); timed per recording.
  3. SINDy beside it: PySINDy with control on the nominal twin's wheel
     residuals, same windows (tools/bench/sindy_baseline.py).
  4. Score: tools/bench/diagnose_scoring.py, the only reader of the keys.

With --out DIR each case's diagnosis (its JSON document, or why it was
refused, its timings and SINDy's result) is kept in DIR/diagnoses as it
comes; --rescore DIR scores such a suite again without generating or
diagnosing anything, for a change of the scorer.

Generation and diagnosis run on --jobs worker processes (one core each;
--workers K gives each diagnosis K processes, as twinbot diagnose
--workers).  A case's seconds are the CPU time of its diagnosis's
processes (one BLAS thread each), scaled to a 90 s recording; its wall
time is kept too, but on a shared machine it measures the other load as
much as diagnosis.
The scoreboard: a row per case, the totals, the targets (MET / MISSED),
and with --json FILE every figure.
"""


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    from tools.arguments import float_range, int_range, output_file, output_folder, suite_folder

    p.add_argument("--cases", type=int_range(1, 10_000), default=40, help="blind cases in the suite (default 40)")
    p.add_argument("--seed", type=int_range(0, 10**9), default=0, help="seed of the first case (default 0)")
    p.add_argument("--split", choices=("tuning", "final"), default="tuning",
                   help="tuning (default): seeds 0..9999, the kinds rules may be set on; final: seeds 100000 + "
                        "--seed on, every kind including the held-back ones (docs/proving-ground.md)")
    p.add_argument("--duration", type=float_range(10, 3600, unit="s"), default=90.0,
                   help="seconds per recording (default 90; diagnosis needs at least 6 windows of 1 s)")
    p.add_argument("--effects", type=int_range(1, 3), default=1,
                   help="effects concealed at once in each in-library case (default 1; 2 or 3 add others, each "
                        "drawn apart, to the same cases: diagnosis selects up to 3)")
    p.add_argument("--drive", choices=DRIVES, default="current",
                   help="the drive of every case's robot (default current, the firmware's; the others give it an "
                        "H-bridge and record the commands in their unit: docs/proving-ground.md \"Drives\")")
    p.add_argument("--jobs", type=int_range(1, 256), default=2, help="worker processes (default 2)")
    p.add_argument("--workers", type=int_range(1, 64), default=1,
                   help="processes per diagnosis, as twinbot diagnose --workers (default 1; with --jobs 1 "
                        "--workers 2 a case's wall time is what a user waits for on two cores)")
    p.add_argument("--out", metavar="DIR", type=output_folder,
                   help="keep the recordings and answer keys here (default: a temporary folder, removed)")
    p.add_argument("--rescore", metavar="DIR", type=suite_folder, nargs="+",
                   help="score again the diagnoses that runs with --out DIR kept, several suites together "
                        "(nothing generated or diagnosed)")
    p.add_argument("--json", metavar="FILE", type=output_file, help="write every figure here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--board-controls", action="store_true",
                   help="also record the firmware on the virtual board over the serial link, idle and with three "
                        "busy processes per core, and diagnose each: both must be a match (tools/bench/board_control.py)")
    # each drive's suite its own section of the page: a PWM robot's score does not replace the current drive's
    p.set_defaults(func=run, markdown_section=lambda args: "diagnose" if args.drive == "current"
                   else f"diagnose-{args.drive}")


# --------------------------------------------------------------------------- #
# The suite
# --------------------------------------------------------------------------- #
def compose_suite(seed: int, n: int, drive: str = "current") -> list[int]:
    """n case seeds from `seed` on, with at least one control and one out-of-library case (n >= 2; which
    cases they are does not depend on --effects, which adds effects to the in-library cases only)."""
    from tools.reference_plant.cases import concealed_names
    from tools.reference_plant.effects import EFFECTS

    seeds = list(range(seed, seed + n))
    unlisted = {name for name, e in EFFECTS.items() if not e.in_library}
    wants = [("control", lambda names: not names), ("out of library", lambda names: bool(set(names) & unlisted))]
    nxt, slot = seed + n, n - 1
    for _label, test in wants if n >= 2 else []:
        if any(test(concealed_names(s, 1, drive)) for s in seeds):
            continue
        while not test(concealed_names(nxt, 1, drive)):
            nxt += 1
        # Swap out a case from the end that is neither a control nor out of the library.
        while slot >= 0 and any(t(concealed_names(seeds[slot], 1, drive)) for _l, t in wants):
            slot -= 1
        seeds[slot] = nxt
        nxt, slot = nxt + 1, slot - 1
    return sorted(seeds)


def generate(seed: int, rec_dir: str, key_dir: str, duration: float, n_effects: int = 1,
             drive: str = "current") -> str:
    """Worker: record case `seed` on the plant; returns the recording's path (its key goes to key_dir)."""
    from tools.reference_plant.cases import make_case

    rec_path, _key = make_case(seed, rec_dir, duration=duration, key_dir=key_dir, n_effects=n_effects, drive=drive)
    return str(rec_path)


def _cpu_seconds() -> float:
    """This process's CPU time and that of its finished children (diagnose's workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def diagnose_blind(rec_path: str, workers: int = 1) -> dict[str, Any]:
    """Worker: diagnosis (on `workers` processes) and the SINDy baseline on one recording, knowing only
    the recording."""
    import warnings

    from host_sim.diagnosis import DiagnosisError, diagnose
    from host_sim.physics.params import params_from_dict
    from host_sim.recordings.recording import load_recording
    from host_sim.physics.world import world_from_dict
    from tools.bench.sindy_baseline import sindy_case

    out: dict[str, Any] = {"recording": rec_path}
    t0, cpu0 = time.perf_counter(), _cpu_seconds()
    rec = load_recording(rec_path)
    params = params_from_dict(rec.meta["robot"], f"{rec_path} (sidecar robot)")
    world = world_from_dict(rec.meta["world"], f"{rec_path} (sidecar world)") if rec.meta.get("world") else None
    try:
        out["diagnosis"] = diagnose(rec, params, world, workers=workers).to_json()
    except DiagnosisError as exc:
        out["error"] = f"refused: {exc}"
    except Exception as exc:  # noqa: BLE001 - a crash is scored as a failure of the case, not of the suite
        out["error"] = f"error: {type(exc).__name__}: {exc}"
        out["traceback"] = traceback.format_exc()
    out["seconds"] = time.perf_counter() - t0
    out["cpu_seconds"] = _cpu_seconds() - cpu0  # the diagnosis's processes: apart from other load on the machine
    out["duration"] = float(rec.t[-1] - rec.t[0] + rec.sample_period)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # STLSQ warns when a threshold removes every term: that is a result
            out["sindy"] = sindy_case(rec, params, world)
    except Exception as exc:  # noqa: BLE001
        out["sindy"] = {"error": f"{type(exc).__name__}: {exc}"}
    return out


def run_suite(seeds: list[int], out_dir: Path, duration: float, jobs: int, quiet: bool,
              workers: int = 1, n_effects: int = 1, drive: str = "current") -> dict[int, dict[str, Any]]:
    """Generate and diagnose every case on `jobs` processes (each diagnosis on `workers`); each case is
    diagnosed once it is recorded."""
    from tqdm import tqdm  # type: ignore[import-untyped]

    rec_dir, key_dir = out_dir / "recordings", out_dir / "answer_keys"
    rec_dir.mkdir(parents=True, exist_ok=True)
    results: dict[int, dict[str, Any]] = {}
    with ProcessPoolExecutor(max_workers=jobs) as pool, \
            tqdm(total=2 * len(seeds), desc="generate + diagnose", unit="step", file=sys.stderr,
                 disable=quiet) as bar:
        pending: dict[Future[Any], tuple[str, int]] = {
            pool.submit(generate, s, str(rec_dir), str(key_dir), duration, n_effects, drive): ("generate", s)
            for s in seeds}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                stage, seed = pending.pop(fut)
                bar.update(1)
                if stage == "generate":
                    pending[pool.submit(diagnose_blind, fut.result(), workers)] = ("diagnose", seed)
                else:
                    results[seed] = fut.result()
                    keep_diagnosis(out_dir, seed, results[seed])
    return results


def keep_diagnosis(out_dir: Path, seed: int, result: dict[str, Any]) -> None:
    """DIR/diagnoses/case_NNNN.json: what --rescore reads, written as each case is done."""
    from tools.arguments import writing

    folder = out_dir / "diagnoses"
    with writing("--out", out_dir):
        folder.mkdir(exist_ok=True)
        (folder / f"case_{seed:04d}.json").write_text(json.dumps(result, indent=1, default=_plain) + "\n")


def _plain(x: Any) -> Any:
    """numpy scalars and arrays as JSON numbers and lists."""
    return x.tolist() if hasattr(x, "tolist") else str(x)


def kept_diagnoses(out_dir: Path) -> tuple[list[int], dict[int, dict[str, Any]]]:
    """The seeds and results a run with --out kept in DIR/diagnoses (keep_diagnosis); ValueError if there
    are none, or one is broken or lacks its recording."""
    files = sorted((out_dir / "diagnoses").glob("case_*.json"))
    if not files:
        raise ValueError(f"{out_dir}: no diagnoses/case_*.json (a suite kept with --out before they were kept?)")
    results: dict[int, dict[str, Any]] = {}
    for f in files:
        try:
            res = json.loads(f.read_text())
            seed = int(f.stem.split("_")[1])
        except (ValueError, IndexError) as exc:
            raise ValueError(f"{f}: not a kept diagnosis ({exc})") from None
        missing = [k for k in ("recording", "seconds", "cpu_seconds", "duration", "sindy") if k not in res]
        if missing:
            raise ValueError(f"{f}: not a kept diagnosis (no {', '.join(missing)})")
        res["recording"] = str(out_dir / "recordings" / Path(res["recording"]).name)  # the suite may have moved
        results[seed] = res
    return sorted(results), results


# --------------------------------------------------------------------------- #
# Scores and totals
# --------------------------------------------------------------------------- #
def score_all(seeds: list[int], results: dict[int, dict[str, Any]], out_dir: Path) -> list[dict[str, Any]]:
    from host_sim.physics.params import params_from_dict
    from host_sim.recordings.recording import load_recording
    from tools.bench import diagnose_scoring as scoring

    rows = []
    for seed in seeds:
        res = results[seed]
        key = scoring.load_key(out_dir / "answer_keys" / f"case_{seed:04d}.answer.json")
        rec = load_recording(res["recording"])
        row = scoring.score_case(key, res.get("diagnosis"), rec, params_from_dict(rec.meta["robot"]), res.get("error"))
        row["excitation"] = key["excitation"]["kind"]
        row["rule_set"] = key["excitation"].get("rule_set")
        row["world"] = key["world"]
        row["seconds"] = res["seconds"]
        row["seconds_per_90s"] = res["seconds"] * REFERENCE_SECONDS / res["duration"]
        row["cpu_seconds"] = res["cpu_seconds"]
        row["cpu_seconds_per_90s"] = res["cpu_seconds"] * REFERENCE_SECONDS / res["duration"]
        sindy = res["sindy"]
        if "error" not in sindy:
            sindy = {**sindy, **{f"names_{k}": v for k, v in scoring.score_sindy(key, sindy["terms"]).items()}}
            sindy["wheel_fit_after"] = min(sindy["fit_after"].values())
        row["sindy"] = sindy
        if "traceback" in res:
            row["traceback"] = res["traceback"]
        rows.append(row)
    return rows


def _share(k: int, n: int) -> float | None:
    return k / n if n else None


def conformal_quantile(scores: list[float], level: float) -> float | None:
    """The split-conformal quantile: the ceil(level (n + 1))-th smallest of n scores (inf when n is too few
    for it), a bound a new score stays within with probability >= level where the scores are exchangeable
    (Vovk et al. 2005; Angelopoulos & Bates 2023, eq. 1).  None without scores."""
    if not scores:
        return None
    k = math.ceil(level * (len(scores) + 1))
    return sorted(scores)[k - 1] if k <= len(scores) else math.inf


def _model_error_totals(named: EffectScores) -> dict[str, Any]:
    """The fit's own intervals' coverage, and the share of the effects' size the model error would have
    needed on this suite (its conformal quantile: how model_error.MODEL_ERROR is set on the tuning split)."""
    fit_alone = [e["param"]["covered_fit"] for _r, e in named if e["param"].get("covered_fit") is not None]
    needed = [e["param"]["share_needed"] for _r, e in named if "share_needed" in e["param"]]
    return {"intervals_covered_fit": sum(fit_alone), "intervals_fit": len(fit_alone),
            "model_error_needed": conformal_quantile(needed, CONFORMAL_LEVEL), "model_error_needed_of": len(needed)}


def totals(rows: list[dict[str, Any]]) -> dict[str, Any]:
    listed = [r for r in rows if r["kind"] == "in library"]
    hidden, excited, named, params_ok = _concealed(listed)
    intervals = [e["param"]["covered"] for _r, e in named if e["param"].get("covered") is not None]
    showing = [r for r in listed if "not_excited" not in r]  # cases that show at least one of their effects
    controls = [r for r in rows if r["kind"] == "control"]
    alarms = [r for r in controls if r["outcome"] != "right"]
    unlisted = [r for r in rows if r["kind"] == "out of library" and "not_excited" not in r]  # shown ones
    flagged = [r for r in unlisted if r["outcome"] == "right"]
    judged = controls + listed
    wheel_ok = [r for r in judged if (r.get("fit_after") or -1e9) >= TARGET_WHEEL_FIT]
    # The target is judged where a perfect twin meets it (scoring.perfect_twin_fit: the plant's own unrounded
    # encoders; a suite without them counts every case); the rest are listed apart.
    unattainable = [r for r in judged if r.get("fit_perfect") is not None and r["fit_perfect"] < TARGET_WHEEL_FIT]
    attainable = [r for r in judged if r not in unattainable]
    attainable_ok = [r for r in attainable if r in wheel_ok]
    outcomes: dict[str, int] = {}
    for r in showing:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    by_drive: dict[str, list[int]] = {}  # drive -> [named, excited] effects
    for r, e in excited:
        counts = by_drive.setdefault(drive_label(r), [0, 0])
        counts[0] += e["named"]
        counts[1] += 1
    # Only diagnoses that ran to a verdict are timed: a crash or a refusal returns early.
    secs = [r["seconds_per_90s"] for r in rows if "fit_before" in r] or [float("nan")]
    cpu = [r["cpu_seconds_per_90s"] for r in rows if "fit_before" in r] or [float("nan")]
    sindy_ok = [r for r in rows if "error" not in r["sindy"]]
    return {
        **_names_not_concealed(rows),
        "cases": len(rows), "in_library": len(listed), "concealed": len(hidden),
        "intervals": len(intervals), "intervals_covered": sum(intervals),
        "coverage_share": _share(sum(intervals), len(intervals)), **_model_error_totals(named),
        "not_excited": len(hidden) - len(excited), "excited": len(excited), "showing": len(showing),
        "outcomes_excited": outcomes, "named_by_drive": by_drive,
        "named": len(named), "named_share": _share(len(named), len(excited)),
        "params_within": len(params_ok), "params_share": _share(len(params_ok), len(named)),
        "param_error_median": statistics.median([e["param"]["error"] for _r, e in named]) if named else None,
        "controls": len(controls), "false_alarms": len(alarms), "false_alarm_share": _share(len(alarms), len(controls)),
        "out_of_library": len(unlisted), "flagged": len(flagged), "flagged_share": _share(len(flagged), len(unlisted)),
        "wheel_judged": len(judged), "wheel_ok": len(wheel_ok), "wheel_share_all": _share(len(wheel_ok), len(judged)),
        "wheel_attainable": len(attainable), "wheel_attainable_ok": len(attainable_ok),
        "wheel_share": _share(len(attainable_ok), len(attainable)),
        "wheel_unattainable": [{"case": r["case"], "fit_after": r.get("fit_after"), "fit_perfect": r["fit_perfect"]}
                               for r in unattainable],
        "perfect_twin_controls": _against_perfect_twin(controls),
        "wheel_fit_before_median": _median([r.get("fit_before") for r in judged]),
        "wheel_fit_after_median": _median([r.get("fit_after") for r in judged]),
        "seconds_median": statistics.median(secs), "seconds_max": max(secs),
        "cpu_seconds_median": statistics.median(cpu), "cpu_seconds_max": max(cpu),
        "sindy": {
            "cases": len(sindy_ok),
            "wheel_fit_after_median": _median([r["sindy"]["wheel_fit_after"] for r in sindy_ok if r in judged]),
            "active_terms_median": _median([r["sindy"]["n_active"] for r in sindy_ok]),
            "named_excited": sum(bool(r["sindy"].get("names_named")) for r in showing if r in sindy_ok),
            "excited": len(showing),
            "silent_controls": sum(bool(r["sindy"].get("names_named")) for r in controls if r in sindy_ok),
            "seconds_median": _median([r["sindy"]["seconds"] for r in sindy_ok]),
        },
    }


def _names_not_concealed(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Of the cases diagnosed, those naming an effect that was not concealed, and how many of each kind."""
    diagnosed = [r for r in rows if "fit_before" in r]
    wrong = [r for r in diagnosed if r.get("not_concealed")]
    return {"diagnosed": len(diagnosed), "naming_not_concealed": len(wrong),
            "naming_not_concealed_by_kind": {k: sum(r["kind"] == k for r in wrong)
                                             for k in sorted({r["kind"] for r in wrong})}}


EffectScores = list[tuple[dict[str, Any], dict[str, Any]]]  # (case row, one of its concealed effects' scores)


def _concealed(listed: list[dict[str, Any]]) -> tuple[EffectScores, EffectScores, EffectScores, EffectScores]:
    """The in-library cases' concealed effects: all, those excited, those named, those with the parameter
    within tolerance.  The named and parameter targets count effects (one per case but with --effects K)."""
    from tools.bench.diagnose_scoring import PARAM_TOLERANCE

    hidden = [(r, e) for r in listed for e in r["effects"]]
    excited = [(r, e) for r, e in hidden if "not_excited" not in e]
    named = [(r, e) for r, e in excited if e["named"]]
    return hidden, excited, named, [(r, e) for r, e in named if e["param"]["error"] <= PARAM_TOLERANCE]


def _against_perfect_twin(controls: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per drive, on the controls with a perfect twin: how far the twin's fit stands under it and diagnosis's
    ceiling over it (percentage points: median, max, count)."""
    out: dict[str, dict[str, Any]] = {}
    for drive in sorted({str(r["excitation"]) for r in controls}):
        rows = [r for r in controls if r["excitation"] == drive and r.get("fit_perfect") is not None
                and r.get("fit_after") is not None]
        if not rows:
            continue
        under = [r["fit_perfect"] - r["fit_after"] for r in rows]
        over = [r["fit_ceiling"] - r["fit_perfect"] for r in rows if r.get("fit_ceiling") is not None]
        out[drive] = {"cases": len(rows), "twin_under_median": statistics.median(under), "twin_under_max": max(under),
                      "ceiling_over_median": _median(over), "ceiling_over_max": max(over) if over else None}
    return out


RULE_SETS = {0: "first", 1: "refined"}  # the firmware's fuzzy rule sets (protocol parameter 4)


def drive_label(row: dict[str, Any]) -> str:
    """What drove a case: the identification manoeuvre, or the firmware's exploration with which rule set."""
    if row["excitation"] != "firmware":
        return str(row["excitation"])
    rules = RULE_SETS.get(int(row["rule_set"])) if row.get("rule_set") is not None else None
    return f"exploration ({rules} rules)" if rules else "exploration"


def _median(values: list[Any]) -> float | None:
    vals = [v for v in values if v is not None]
    return float(statistics.median(vals)) if vals else None


def targets(t: dict[str, Any]) -> list[dict[str, Any]]:
    from tools.bench.diagnose_scoring import PARAM_TOLERANCE

    def met(share: float | None, ok: bool) -> bool | None:
        return None if share is None else ok

    fa = t["false_alarm_share"]
    return [
        {"name": "named", "met": met(t["named_share"], (t["named_share"] or 0) >= TARGET_NAMED),
         "text": f">= {TARGET_NAMED:.0%} of concealed in-library effects named correctly with the right wheel/sensor: "
                 f"{t['named']}/{t['excited']} ({_pct(t['named_share'])}; {t['not_excited']} not excited, apart)"},
        {"name": "params", "met": met(t["params_share"], (t["params_share"] or 0) >= TARGET_PARAMS),
         "text": f"parameters within {PARAM_TOLERANCE:.0%} (>= {TARGET_PARAMS:.0%} of those named): "
                 f"{t['params_within']}/{t['named']} ({_pct(t['params_share'])})"},
        {"name": "wheel_fit", "met": met(t["wheel_share"], (t["wheel_share"] or 0) >= TARGET_WHEEL_SHARE),
         "text": f"held-out fit after >= {TARGET_WHEEL_FIT:.0f} % on both wheel speeds, in >= {TARGET_WHEEL_SHARE:.0%} "
                 f"of the controls and in-library cases where a perfect twin reaches it: "
                 f"{t['wheel_attainable_ok']}/{t['wheel_attainable']} ({_pct(t['wheel_share'])}; "
                 f"{len(t['wheel_unattainable'])} where it does not, apart; in all {t['wheel_ok']}/{t['wheel_judged']})"},
        {"name": "false_alarms", "met": met(fa, (fa if fa is not None else 1) <= TARGET_FALSE_ALARMS),
         "text": f"false alarms on effect-free controls <= {TARGET_FALSE_ALARMS:.0%}: {t['false_alarms']}/"
                 f"{t['controls']} ({_pct(fa)})"},
        {"name": "out_of_library", "met": met(t["flagged_share"], (t["flagged_share"] or 0) >= TARGET_UNLISTED),
         "text": f"out-of-library effect -> unexplained / partly explained where it shows, no library effect "
                 f"named (one as `closest` only is allowed), >= "
                 f"{TARGET_UNLISTED:.0%}: {t['flagged']}/{t['out_of_library']} ({_pct(t['flagged_share'])})"},
        {"name": "coverage", "met": met(t["coverage_share"], TARGET_COVERAGE[0] <= (t["coverage_share"] or 0)
                                        <= TARGET_COVERAGE[1]),
         "text": f"95 % intervals of the named effects holding the drawn truth, {TARGET_COVERAGE[0]:.0%}-"
                 f"{TARGET_COVERAGE[1]:.0%}: {t['intervals_covered']}/{t['intervals']} ({_pct(t['coverage_share'])})"},
        {"name": "seconds", "met": None if t["cpu_seconds_median"] != t["cpu_seconds_median"]
            else t["cpu_seconds_median"] <= TARGET_SECONDS and t["cpu_seconds_max"] <= TARGET_SECONDS_MAX,
         "text": f"<= {TARGET_SECONDS:.0f} s median, {TARGET_SECONDS_MAX:.0f} s max per {REFERENCE_SECONDS:.0f} s "
                 f"recording (over the diagnoses that "
                 f"reached a verdict; CPU time of its processes): {t['cpu_seconds_median']:.1f} s "
                 f"(max {t['cpu_seconds_max']:.1f} s; wall {t['seconds_median']:.1f} s, max {t['seconds_max']:.1f} s, "
                 f"on the machine's load)"},
    ]


def board_controls(out: Path | None, duration: float) -> list[dict[str, Any]]:
    """The virtual board recorded idle and oversubscribed, each diagnosed (tools/bench/board_control.py)."""
    from tools.bench.board_control import format_rows, run_board_controls

    with tempfile.TemporaryDirectory(prefix="twinbot-board-control-") as tmp:
        rows = run_board_controls((out or Path(tmp)) / "board_controls", duration)
    print("\n".join(format_rows(rows)))
    return rows


def board_target(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = sum(r["verdict"] == "match" for r in rows)
    return {"name": "board_controls", "met": ok == len(rows),
            "text": f"the virtual board over the serial link, idle and with the cores oversubscribed, a match: "
                    f"{ok}/{len(rows)} (" + ", ".join(f"{r['busy']} busy: {r['verdict']}, {r['late_share']:.0%} "
                                                       f"rows late" for r in rows) + ")"}


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


# --------------------------------------------------------------------------- #
# The scoreboard
# --------------------------------------------------------------------------- #
HEADER = ("case", "concealed", "drive", "verdict", "diagnosis named", "outcome", "param err", "wheels fit",
          "cpu s/90s", "SINDy fit", "terms", "SINDy names")


def case_row(r: dict[str, Any]) -> tuple[str, ...]:
    outcome = "not excited" if "not_excited" in r else r["outcome"]
    if "not_excited" in r and r["outcome"] == "right":
        outcome = "not excited (named)"
    param = ", ".join(f"{100 * e['param']['error']:.0f} %" if "param" in e else "-" for e in r.get("effects", [])) or "-"
    bound = (f"p {_f(r['fit_perfect'])}" if r.get("fit_perfect") is not None else f"c {_f(r.get('fit_ceiling'))}")
    fit = f"{_f(r.get('fit_before'))} -> {_f(r.get('fit_after'))} ({bound})" if "fit_before" in r else "-"
    s = r["sindy"]
    sindy = ("error", "-", "-") if "error" in s else (
        f"{_f(s['wheel_fit_after'])}", str(s["n_active"]), "yes" if s["names_named"] else "no")
    verdict = str(r["verdict"])
    return (r["case"].replace("case_", ""), r["truth"], r["excitation"], verdict[:40], _clip(r["named"], 44),
            outcome, param, fit, f"{r['cpu_seconds_per_90s']:.1f}", *sindy)


def _f(x: float | None) -> str:
    return "-" if x is None else f"{x:.0f}"


def _f2(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def _clip(text: str, n: int) -> str:
    return text if len(text) <= n else text[:n - 1] + "~"


def format_table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    widths = [max(len(row[i]) for row in rows + [header]) for i in range(len(header))]
    lines = [" | ".join(c.ljust(w) for c, w in zip(header, widths)), "-+-".join("-" * w for w in widths)]
    return "\n".join(lines + [" | ".join(c.ljust(w) for c, w in zip(row, widths)) for row in rows])


def print_intervals(t: dict[str, Any]) -> None:
    print(f"95 % intervals holding the truth: {t['intervals_covered']}/{t['intervals']} as reported, "
          f"{t['intervals_covered_fit']}/{t['intervals_fit']} with the fit's spread alone (the model error they add: "
          f"{MODEL_ERROR:.0%} of the effect's size); the share that would have held {CONFORMAL_LEVEL:.0%} here "
          f"(conformal, over {t['model_error_needed_of']}): "
          + ("too few to say" if t["model_error_needed"] == math.inf else _pct(t["model_error_needed"])))


def print_report(report: dict[str, Any]) -> None:
    m, t = report["machine"], report["totals"]
    print("twinbot bench diagnose")
    print(f"command:     {report['command']}")
    print(f"machine:     {m['platform']}, {m['processor']}, {m['cpus']} CPUs, load average {m['load']}")
    print(f"python:      CPython {m['python']}, numpy {m['numpy']}, pysindy {m['pysindy']}, BLAS threads "
          f"{m['blas_threads']}; {report['jobs']} worker process{'es' if report['jobs'] != 1 else ''}, "
          f"{report.get('workers', 1)} per diagnosis")
    held = "" if t["concealed"] == t["in_library"] else f" ({t['concealed']} effects between them)"
    print(f"suite:       {t['cases']} cases of {report['duration']:g} s: {t['in_library']} with in-library "
          f"effects{held}, {t['controls']} controls, {t['out_of_library']} out of library; seeds {report['seeds']}")
    print()
    print(format_table(HEADER, [case_row(r) for r in report["cases"]]))
    print()
    print("wheels fit: held-out fit % of the worse wheel, nominal twin -> fitted twin (p: a perfect twin's, the plant's "
          "own unrounded encoders; c, where the suite has no truth: diagnosis's own ceiling);")
    print("SINDy fit: the same windows, nominal twin + SINDy's correction; terms: its active terms (of "
          f"{report['cases'][0]['sindy'].get('n_library', '?')}); SINDy names: tools/bench/diagnose_scoring.py")
    for r in report["cases"]:
        for e in r.get("effects", []):
            if "not_excited" in e:
                which = f" {e['truth']}" if len(r["effects"]) > 1 else ""
                print(f"  {r['case']}:{which} not excited: {e['not_excited']}")
        if str(r["verdict"]).startswith(("error", "refused")):
            print(f"  {r['case']}: {r['verdict']}")
    print()
    print(f"outcomes of the {t['showing']} in-library cases that show their effect: "
          + ", ".join(f"{k} {v}" for k, v in sorted(t["outcomes_excited"].items())))
    print("named, by what drove the robot: "
          + ", ".join(f"{k} {named}/{n}" for k, (named, n) in sorted(t["named_by_drive"].items())))
    kinds = ", ".join(f"{k} {n}" for k, n in t["naming_not_concealed_by_kind"].items())
    print(f"cases naming an effect that was not concealed (on a control, beside a right name or instead of one): "
          f"{t['naming_not_concealed']}/{t['diagnosed']}" + (f" ({kinds})" if kinds else ""))
    print_intervals(t)
    print(f"median parameter error of those named: "
          + ("-" if t["param_error_median"] is None else f"{100 * t['param_error_median']:.0f} %"))
    print(f"median held-out wheel fit (controls + in-library): before {_f(t['wheel_fit_before_median'])} %, "
          f"after diagnosis {_f(t['wheel_fit_after_median'])} %, "
          f"with SINDy {_f(t['sindy']['wheel_fit_after_median'])} %")
    apart = t["wheel_unattainable"]
    print(f"held-out wheel fit under {TARGET_WHEEL_FIT:.0f} % after diagnosis: {t['wheel_judged'] - t['wheel_ok']} "
          f"cases, {sum((r['fit_after'] or -1e9) < TARGET_WHEEL_FIT for r in apart)} of them where a perfect twin "
          f"scores under {TARGET_WHEEL_FIT:.0f} % too")
    if apart:
        print(f"apart from the wheel-fit target, a perfect twin under {TARGET_WHEEL_FIT:.0f} % (the encoders' rounding "
              f"is most of what the wheels vary by; fitted / perfect): "
              + ", ".join(f"{r['case'].replace('case_', '')} {_f(r['fit_after'])}/{_f(r['fit_perfect'])}" for r in apart))
    for drive, g in t.get("perfect_twin_controls", {}).items():
        print(f"controls, {drive}: the twin's fit under the perfect twin's by {g['twin_under_median']:.2f} points "
              f"(median of {g['cases']}; max {g['twin_under_max']:.2f}); diagnosis's ceiling over it by "
              f"{_f2(g['ceiling_over_median'])} (max {_f2(g['ceiling_over_max'])})")
    s = t["sindy"]
    print(f"SINDy: median {_f(s['active_terms_median'])} active terms; its signature terms alone name the effects "
          f"in {s['named_excited']}/{s['excited']} in-library cases that show them; silent on {s['silent_controls']}/"
          f"{t['controls']} controls; {s['seconds_median'] or 0:.2f} s per case")
    print_targets(report["targets"])
    print(f"\nelapsed: {report['elapsed_s']:.1f} s")


def run(args: argparse.Namespace) -> int:
    from tools.bench.sim import _machine, pin_blas_threads

    blas = pin_blas_threads()
    t_start = time.monotonic()
    if args.rescore:
        if args.out:
            print("twinbot bench diagnose: error: --rescore scores a kept suite; --out keeps a new one: "
                  "give one of them", file=sys.stderr)
            return 2
        seeds, rows, durations = [], [], []
        try:
            for folder in args.rescore:
                kept, results = kept_diagnoses(Path(folder))
                seeds += kept
                rows += score_all(kept, results, Path(folder))
                durations += [r["duration"] for r in results.values()]
        except (OSError, ValueError) as exc:  # a missing or broken key or recording: the loaders' one-line errors
            print(f"twinbot bench diagnose: error: {exc}", file=sys.stderr)
            return 2
        # to 0.1 s: a recording's span jitters with the firmware's period (docs/proving-ground.md, "Timing")
        args.duration = round(statistics.median(durations), 1)
        command = f"twinbot bench diagnose --rescore {' '.join(args.rescore)} (the timings are the kept runs')"
    else:
        from tools.reference_plant.cases import first_seed

        seeds = compose_suite(first_seed(args.split, args.seed), args.cases, args.drive)
        with tempfile.TemporaryDirectory(prefix="twinbot-bench-diagnose-") as tmp:
            out_dir = Path(args.out) if args.out else Path(tmp)
            results = run_suite(seeds, out_dir, args.duration, args.jobs, args.quiet, args.workers, args.effects,
                                args.drive)
            rows = score_all(seeds, results, out_dir)
        command = (f"twinbot bench diagnose --cases {args.cases} --seed {args.seed} --split {args.split} "
                   f"--duration {args.duration:g} "
                   f"--jobs {args.jobs}" + (f" --workers {args.workers}" if args.workers > 1 else "")
                   + (f" --effects {args.effects}" if args.effects > 1 else "")
                   + (f" --drive {args.drive}" if args.drive != "current" else ""))
    import pysindy  # type: ignore[import-untyped]

    report: dict[str, Any] = {
        "command": command, "seeds": seeds, "duration": args.duration, "jobs": args.jobs,
        "workers": args.workers,
        "machine": {**_machine(blas), "pysindy": pysindy.__version__}, "cases": rows}
    report["totals"] = totals(rows)
    report["targets"] = targets(report["totals"])
    if args.board_controls:
        report["board_controls"] = board_controls(Path(args.out) if args.out else None, args.duration)
        report["targets"].append(board_target(report["board_controls"]))
        command += " --board-controls"
        report["command"] = command
    report["elapsed_s"] = time.monotonic() - t_start
    print_report(report)
    if args.json:
        from tools.arguments import writing

        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(report, indent=1, default=str) + "\n")
    return 0
