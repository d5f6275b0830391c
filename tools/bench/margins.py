"""`twinbot bench margins`: how far each of the diagnosis's locate rules stands from its threshold.

On every recording of a blind suite, the nominal twin is compared in 1 s windows and each locate rule's
margin taken (host_sim.diagnosis.compare.rule_margins).  docs/diagnosis.md, "How near the rules come".
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from tools.bench.report import print_targets

RULES = ("bias", "scale", "scatter", "timing", "lag")
# The concealed effects (tools/reference_plant/effects.py) each rule is there to find; bias: the rest of the library.
MEANT_FOR = {"scale": ("wheel_radius", "track_width", "encoder_scale"), "scatter": ("traction_limit", "backlash"),
             "timing": ("ir_latency",), "lag": ("actuator_delay",)}

DESCRIPTION = """\
On every recording of a blind suite (generated as `twinbot bench diagnose`
generates it, or one it kept: --suite DIR, its --out DIR), the nominal twin
is compared with the recording in 1 s windows, and each locate rule's
margin taken (host_sim.diagnosis.compare.rule_margins): the weakest of the
rule's tests as a ratio to its threshold, the largest over the channels
the rule judges.  At 1 or more the rule locates something.

  bias     a regime bin's mean residual: |z| >= 5, 1 noise level, 5 % of the signal
  scale    a window total's proportional error: |z| >= 5, 2 % (1 % for a count),
           over 1 s windows and over 5 s
  scatter  a wheel's residual RMS: 5 noise levels (or 8 encoder roundings), 5 % of its speed
  timing   IR readings behind (or ahead of) the pose: both halves at |z| >= 3,
           on the third of the sensors that show it the same way round; or
           each reading's lag behind its change at |z| >= 4, on the third
  lag      a wheel behind (or ahead of) the twin whenever its speed changes:
           |z| >= 5, 8 ms

Recordings too short to diagnose are listed and left out; those with too
little data to call a match (too still, pressed against walls) are judged
all the same, since a mismatch located there is diagnosed, and listed.
The table: a row per recording (the answer key is read only to label
it), then per rule the largest margin on the effect-free
controls (below 1, or the rule raises a false alarm) and, on the cases
whose effect the rule is there to find, how many reach 1, the smallest
margin, and how many some rule locates (a latency that shows as a bias on
one sensor is located before the ring's timing is asked): the headroom
the thresholds were set in.

    twinbot bench diagnose --cases 40 --seed 80 --out suite80
    twinbot bench margins --suite suite80        # the same recordings, no new ones
"""


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    from tools.arguments import float_range, int_range, output_file, output_folder, suite_folder

    p.add_argument("--suite", metavar="DIR", type=suite_folder,
                   help="judge this suite (DIR/recordings, DIR/answer_keys: what 'twinbot bench diagnose --out DIR' "
                        "kept) instead of generating one")
    p.add_argument("--cases", type=int_range(1, 10_000), default=40, help="cases to generate (default 40)")
    p.add_argument("--seed", type=int_range(0, 10**9), default=0, help="seed of the first case (default 0)")
    p.add_argument("--duration", type=float_range(10, 3600, unit="s"), default=90.0,
                   help="seconds per generated recording (default 90)")
    p.add_argument("--jobs", type=int_range(1, 256), default=2, help="worker processes (default 2)")
    p.add_argument("--out", metavar="DIR", type=output_folder, help="keep a generated suite here")
    p.add_argument("--json", metavar="FILE", type=output_file, help="write every figure here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def margins_of(rec_path: str) -> dict[str, Any]:
    """Worker: every rule's margin on one recording against the nominal twin of its sidecar, or why the
    diagnosis refuses it."""
    from host_sim.diagnosis import DiagnosisError
    from host_sim.diagnosis.compare import compare_all, rule_margins
    from host_sim.diagnosis.report import TooLittleData, check_data, check_judgeable
    from host_sim.physics.params import params_from_dict
    from host_sim.recordings.recording import load_recording
    from host_sim.physics.world import world_from_dict

    try:
        rec = load_recording(rec_path)
        params = params_from_dict(rec.meta["robot"], f"{rec_path} (sidecar robot)")
        world = world_from_dict(rec.meta["world"], f"{rec_path} (sidecar world)") if rec.meta.get("world") else None
    except ValueError as exc:  # the loaders' one-line errors (RecordingError, ParamsError, ... are ValueErrors)
        return {"recording": rec_path, "error": str(exc)}
    try:
        check_data(rec, world)
    except DiagnosisError as exc:
        return {"recording": rec_path, "refused": str(exc)}
    comparisons = compare_all(rec, params, world, locate=False)
    first = comparisons[0]
    longer = comparisons[-1] if len(comparisons) > 1 else None
    out: dict[str, Any] = {"recording": rec_path, "margins": rule_margins(first, rec, params, world, longer)}
    try:
        check_judgeable(rec, first)
    except TooLittleData as exc:  # judged all the same: a mismatch located there is diagnosed (a match refused)
        out["little_data"] = exc.shortfall
    return out


def suite_paths(args: argparse.Namespace, out_dir: Path) -> list[Path]:
    """The suite's recordings: --suite's, or a suite generated into out_dir."""
    if args.suite:
        return sorted(Path(args.suite, "recordings").glob("case_*.csv"))
    from tqdm import tqdm  # type: ignore[import-untyped]

    from tools.bench.diagnose import compose_suite, generate

    seeds = compose_suite(args.seed, args.cases)
    rec_dir, key_dir = out_dir / "recordings", out_dir / "answer_keys"
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        jobs = [pool.submit(generate, s, str(rec_dir), str(key_dir), args.duration) for s in seeds]
        return [Path(j.result()) for j in tqdm(jobs, desc="generate", unit="case", file=sys.stderr,
                                               disable=args.quiet)]


def label(path: Path) -> dict[str, Any]:
    """What the answer key says of a recording, for its row: the concealed effects and the excitation."""
    key_path = path.parent.parent / "answer_keys" / f"{path.stem}.answer.json"
    if not key_path.is_file():  # judged, but left out of the summary: nobody can say what it concealed
        return {"case": path.stem, "effects": [], "control": False, "drive": "-", "in_library": [],
                "unlabelled": True}
    key = json.loads(key_path.read_text())
    effects = [e["name"] for e in key["effects"]]
    return {"case": path.stem, "effects": effects, "control": not effects, "drive": key["excitation"]["kind"],
            "in_library": [e["name"] for e in key["effects"] if e["in_library"]]}


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per rule: the controls' largest margin, and the cases the rule is for, reached and the smallest."""
    judged = [r for r in rows if "margins" in r and not r.get("unlabelled")]
    special = {e for names in MEANT_FOR.values() for e in names}
    out = []
    for rule in RULES:
        controls = [(r["margins"][rule][0], r["case"]) for r in judged if r["control"]]
        if rule in MEANT_FOR:
            meant = [r for r in judged if set(r["effects"]) & set(MEANT_FOR[rule])]
        else:  # the in-library effects no other rule is there for
            meant = [r for r in judged if set(r["in_library"]) - special]
        cases = [(r["margins"][rule][0], r["case"]) for r in meant]
        out.append({"rule": rule, "controls": len(controls), "controls_max": max(controls, default=None),
                    "for": ", ".join(MEANT_FOR.get(rule, ("the rest of the library",))), "cases": len(cases),
                    "reached": sum(m >= 1.0 for m, _c in cases), "cases_min": min(cases, default=None),
                    "located": sum(any(m >= 1.0 for m, _w in r["margins"].values()) for r in meant)})
    return out


def _m(pair: tuple[float, str] | list[Any] | None) -> str:
    if pair is None:
        return "-"
    return f"{pair[0]:.2f} ({pair[1]})" if pair[1] else f"{pair[0]:.2f}"


def print_report(report: dict[str, Any]) -> None:
    from tools.bench.diagnose import format_table

    m = report["machine"]
    print("twinbot bench margins")
    print(f"command:     {report['command']}")
    print(f"machine:     {m['platform']}, {m['processor']}, {m['cpus']} CPUs, load average {m['load']}")
    print()
    rows = [(r["case"], "no answer key" if r.get("unlabelled") else ",".join(r["effects"]) or "control", r["drive"],
             *([_m(r["margins"][rule]) for rule in RULES] if "margins" in r else
               ["refused" if "refused" in r else "unreadable"] + [""] * (len(RULES) - 1)))
            for r in report["cases"]]
    print(format_table(("case", "concealed", "drive", *RULES), rows))
    for r in report["cases"]:
        if "refused" in r or "error" in r:
            print(f"  {r['case']}: {'refused' if 'refused' in r else 'unreadable'}: {r.get('refused', r.get('error'))}")
        elif "little_data" in r:
            print(f"  {r['case']}: little data (a match would be refused): {r['little_data']}")
    print()
    print(format_table(("rule", "controls: largest margin", "cases it is for: reached", "smallest margin",
                        "by any rule", "for"),
                       [(s["rule"], _m(s["controls_max"]), f"{s['reached']}/{s['cases']}", _m(s["cases_min"]),
                         f"{s['located']}/{s['cases']}", s["for"]) for s in report["summary"]]))
    print_targets(report["targets"])
    print(f"\nelapsed: {report['elapsed_s']:.1f} s")


def targets(summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    worst = max((s["controls_max"] for s in summary if s["controls_max"] is not None), default=None)
    return [{"text": "every rule stays below 1 on every judged control (no false alarm in the making)"
                     + ("" if worst is None else f": largest {worst[0]:.2f} ({worst[1]})"),
             "met": None if worst is None else worst[0] < 1.0}]


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm  # type: ignore[import-untyped]

    from tools.bench.sim import _machine, pin_blas_threads

    blas = pin_blas_threads()
    t_start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="twinbot-bench-margins-") as tmp:
        paths = suite_paths(args, Path(args.out) if args.out else Path(tmp))
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            results = list(tqdm(pool.map(margins_of, [str(p) for p in paths]), total=len(paths), desc="margins",
                                unit="recording", file=sys.stderr, disable=args.quiet))
        rows = [{**label(p), **r} for p, r in zip(paths, results)]
    command = (f"twinbot bench margins --suite {args.suite}" if args.suite else
               f"twinbot bench margins --cases {args.cases} --seed {args.seed} --duration {args.duration:g}")
    report: dict[str, Any] = {"command": command, "machine": _machine(blas), "cases": rows,
                              "summary": summarise(rows)}
    report["targets"] = targets(report["summary"])
    report["elapsed_s"] = time.monotonic() - t_start
    print_report(report)
    if args.json:
        from tools.arguments import writing

        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(report, indent=1) + "\n")
    return 0
