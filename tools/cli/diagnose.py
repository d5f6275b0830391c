"""`twinbot diagnose`: where a recording and the twin disagree, in physical terms (docs/diagnosis.md)."""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from tools.arguments import float_range, input_file, int_range, output_file, writing
from tools.arguments import CliError

DESCRIPTION = """\
The twin replays the recording in windows (1 s and 5 s) from the recorded
state, driven open loop by the recorded current references.  Every channel
(each wheel's encoder, the body's motion and pose where a tracker recorded
it, each IR sensor's reflected and ambient light, the battery) is judged on
held-out windows; where the residuals are not noise, the mismatch is located
by regime (speed, acceleration, turning, direction, command, heading, battery,
distance to the walls) and by time, and said in words.  Effects from the
library are then fitted and kept only if they improve the held-out windows,
and the verdict is judged on those held-out windows.  Before any effect, the
twin is calibrated within the datasheet's tolerance (each wheel's radius,
torque constant and friction, the track, the battery, each sensor's gain;
--tolerance FILE gives other bands): a robot built within it is a match, and
an effect is named only beyond it, and only where the twin fitted with it
leaves none of the channels it answers for located.  Opt-in: --test-fraction F
(the last F of the windows) or --test REC2.csv (a second recording) is a test
block that no fit nor rule sees, and the verdict is judged there instead: an
effect is named only if the twin fitted with it leaves noise there (near its
noise, white, with no trend in time), and a match needs the nominal twin to.

Verdicts: match (the twin reproduces the recording to its noise), explained,
partly explained, unexplained (located, but nothing in the library of effects
names it).  The JSON document is described in docs/diagnosis.md.

What it needs: 6 s at least, 13 s with a test block (60-90 s is better), with the wheels turning
(or driven, away from the walls) in a fifth of the periods, and 6 windows
of 1 s away from the walls; a tracker's pose for the body's motion and the
IR sensors.  Less is refused with a one-line reason and exit status 2.  The
identification manoeuvre records all of it:
twinbot serial PORT --excite --record run.csv (twinbot sim --excite on the twin).
--workers screens the library and fits the shortlisted effects side by side:
the same verdict and figures, sooner.  A progress line per step goes to
stderr (--quiet: none).  How long it takes: twinbot bench diagnose.
"""


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="examples:\n  twinbot diagnose run.csv\n"
                              "  twinbot diagnose run.csv --params my_robot.json --json verdict.json")
    p.add_argument("recording", type=input_file, help="a recording (FILE.csv with its FILE.csv.json sidecar)")
    p.add_argument("--params", metavar="FILE", type=input_file, help="the twin's robot parameters (default: the recording's sidecar)")
    p.add_argument("--world", metavar="NAME|FILE", help="the walls (default: the recording's sidecar)")
    p.add_argument("--json", metavar="FILE", type=output_file, help="write the verdict and its evidence as JSON")
    p.add_argument("--html", metavar="FILE", type=output_file, help="write a self-contained report with the pictures")
    p.add_argument("--write-params", metavar="FILE", type=output_file,
                   help="write the fitted twin as a robot parameter file (twinbot sim --params FILE loads it)")
    p.add_argument("--workers", type=int_range(1, 64),
                   help="processes that screen and fit the effects side by side: the same verdict and figures, "
                        f"sooner (default on Linux: one per core, {os.cpu_count()} here, up to the effects fitted "
                        "at a time; elsewhere 1, which runs it all in this process)")
    block = p.add_mutually_exclusive_group()  # opt-in: without either, no test block (judged as before)
    block.add_argument("--test", metavar="REC2.csv", type=input_file,
                       help="a second recording of the same robot and world: the test block the verdict is judged "
                            "on, with its rules (default: no test block; the held-out windows are judged)")
    block.add_argument("--test-fraction", metavar="F", type=float_range(0.0, 0.9, lo_open=True),
                       help="keep the last F of the 1 s windows (0.25: a quarter; at least 6 windows) as a test "
                            "block that no fit nor rule sees, the verdict judged there with its rules "
                            "(default: no test block)")
    p.add_argument("--tolerance", metavar="FILE", type=input_file,
                   help="the datasheet's tolerance, relative bands by value (an angle in rad for ir_misalignment): "
                        "{\"wheel_radius\": 0.01, ...} "
                        "(default: docs/diagnosis.md, \"Within the datasheet's tolerance\"; 0 turns one off)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=run)


def default_workers() -> int:
    """The machine's cores, at most as many as effects are fitted side by side; one but on Linux (the
    workers fork, which macOS's system libraries do not all survive)."""
    from host_sim.diagnosis.fit import SHORTLIST

    return min(os.cpu_count() or 1, SHORTLIST) if sys.platform.startswith("linux") else 1


def load(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from host_sim.physics.params import DEFAULT, ParamsError, load_params, params_from_dict
    from host_sim.recordings.checks import check_recording
    from host_sim.recordings.recording import RecordingError, load_recording
    from host_sim.physics.world import WorldError, world_by_name_or_path, world_from_dict
    from host_sim.diagnosis.tolerance import ToleranceError, load_bands

    try:
        args.bands = load_bands(args.tolerance) if getattr(args, "tolerance", None) else None
        rec = load_recording(args.recording, ordered_times=False)
        test = load_recording(args.test, ordered_times=False) if getattr(args, "test", None) else None
        if args.params:
            params = load_params(args.params)
        elif isinstance(rec.meta.get("robot"), dict) and rec.meta["robot"]:
            params = params_from_dict(rec.meta["robot"], f"{args.recording} (sidecar robot)")
        else:
            params = DEFAULT
        if args.world:
            world = world_by_name_or_path(args.world, params.body_radius)
        elif isinstance(rec.meta.get("world"), dict):
            world = world_from_dict(rec.meta["world"], f"{args.recording} (sidecar world)")
        else:
            world = None
        rec = check_recording(rec, params)  # the test recording too: both are replayed by the same twin
        test = check_recording(test, params) if test is not None else None
    except (RecordingError, ParamsError, WorldError, ToleranceError) as exc:
        raise CliError(str(exc)) from None
    return rec, params, world, test


def run(args: argparse.Namespace) -> int:
    from host_sim.diagnosis import DiagnosisError, diagnose

    rec, params, world, test = load(args)

    def progress(stage: str) -> None:
        if not args.quiet:
            print(f"  ... {stage}", file=sys.stderr, flush=True)

    try:
        result = diagnose(rec, params, world, progress=progress, workers=args.workers or default_workers(),
                          test_block=test if test is not None else args.test_fraction, bands=args.bands)
    except DiagnosisError as exc:
        raise CliError(f"{args.recording}: {exc}") from None
    print(result.summary())
    if args.json:
        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(result.to_json(), indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.html:
        from host_sim.diagnosis.html import render

        page = render(rec, result)
        with writing("--html", args.html):
            Path(args.html).write_text(page, encoding="utf-8")
        print(f"wrote {args.html}")
    if args.write_params:
        fitted = (result.model.params if result.model is not None
                  else result.calibration.params if result.calibration is not None else params)
        with writing("--write-params", args.write_params):
            Path(args.write_params).write_text(json.dumps(fitted.to_json(), indent=1) + "\n")
        from host_sim.controller.hardware_io import FIRMWARE_DRIVES

        use = "sim" if fitted.drive_kind in FIRMWARE_DRIVES else "replay"  # the drives the firmware can run
        print(f"wrote {args.write_params}: the twin with {len(result.effects)} fitted effect(s); "
              f"use it with twinbot {use} --params {args.write_params}")
    return 0
