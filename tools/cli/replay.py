"""`twinbot replay REC.csv`: a recording's commands, open loop, through the twin.

The twin starts in the state recorded at --start (row 0 by default), is fed the recorded
current references, and the command prints how far its encoders and pose end from the
recorded ones, and the largest gap on the way: 0 ticks and 0 mm for a simulator recording, the
twin's distance from the robot for a real one.  Parameters and world come from the sidecar
unless --params / --world say otherwise.  Without a world (a real robot's recording) the
drive alone is replayed, in an empty world: the encoders, and the pose where a tracker
recorded it.  docs/recordings.md.
"""
from __future__ import annotations

import argparse
import math
from typing import Any

from tools.arguments import image_file, input_file, int_range, non_negative_int, writing
from tools.arguments import CliError

EXAMPLES = """\
examples:
  twinbot sim --world maze --duration 30 --record run.csv && twinbot replay run.csv
  twinbot replay robot.csv --world paper_room --params robot.json --png replay.png
  twinbot replay run.csv --start 250                 from the state recorded at row 250
"""


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=__doc__.split("\n\n", 1)[1], epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", metavar="REC.csv", type=input_file, help="a recording (CSV + JSON sidecar)")
    add_source_arguments(p)
    p.add_argument("--start", type=non_negative_int, default=0, metavar="ROW",
                   help="replay from the state recorded at this row (default 0)")
    p.add_argument("--substeps", type=int_range(1, 1000), default=None,
                   help="physics substeps per control period (default: the recording's, else 8)")
    p.add_argument("--png", metavar="FILE", type=image_file, help="draw the recording and the twin's track")
    p.set_defaults(func=run)


def add_source_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--world", help="built-in world or world JSON file (default: the recording's)")
    p.add_argument("--params", metavar="FILE", type=input_file,
                   help="robot parameters JSON (default: the recording's)")


def load_inputs(args: argparse.Namespace) -> tuple[Any, Any, Any]:
    """(recording, robot parameters, world or None): each from its option, else from the sidecar."""
    from host_sim.physics.params import DEFAULT, ParamsError, load_params, params_from_dict
    from host_sim.recordings.checks import check_recording
    from host_sim.recordings.recording import RecordingError, load_recording, sidecar_path
    from host_sim.physics.world import WorldError, world_by_name_or_path, world_from_dict

    try:
        rec = load_recording(args.recording, ordered_times=False)
        side = str(sidecar_path(args.recording))
        robot = rec.meta.get("robot")
        if args.params:
            params = load_params(args.params)
        else:
            params = params_from_dict(robot, f"{side}: robot") if robot else DEFAULT
        rec = check_recording(rec, params)
        world = None
        if args.world:
            world = world_by_name_or_path(args.world, params.body_radius)
        elif rec.meta.get("world"):
            world = world_from_dict(rec.meta["world"], f"{side}: world", params.body_radius)
    except (RecordingError, ParamsError, WorldError) as exc:
        raise CliError(str(exc)) from None
    if not len(rec):
        raise CliError(f"{args.recording}: the recording has no rows")
    return rec, params, world


def run(args: argparse.Namespace) -> int:
    import numpy as np

    rec, params, world = load_inputs(args)
    if args.start >= len(rec):
        raise CliError(f"--start {args.start}: the recording has rows 0..{len(rec) - 1}")
    result, where = _replay(args, rec, params, world)
    rows = slice(args.start, len(rec))
    enc_gap = result.enc - rec.enc[rows]
    duration = float(rec.t[-1] - rec.t[args.start])
    print(f"replayed {args.recording}: rows {args.start}..{len(rec) - 1} ({duration:.2f} s), open loop through "
          f"the twin {where}")
    print_notes(rec)
    print(f"  encoders at the end: twin {result.enc[-1, 0]}/{result.enc[-1, 1]}, recorded "
          f"{rec.enc[-1, 0]}/{rec.enc[-1, 1]} ticks (left/right): {_ticks(enc_gap[-1])} apart; "
          f"largest gap on the way {int(np.abs(enc_gap).max())} ticks")
    tracked = rec.pose_rows[rows]
    if tracked.any() and tracked[0]:  # the twin started on the tracked pose: the two can be compared
        last = int(np.flatnonzero(tracked)[-1])
        gap = np.hypot(*(result.pose[tracked, :2] - rec.pose[rows][tracked, :2]).T)
        dphi = float(np.angle(np.exp(1j * (result.pose[last, 2] - rec.pose[args.start + last, 2]))))
        print(f"  pose at the end: {1000 * gap[-1]:.1f} mm and {math.degrees(dphi):+.2f} degrees from the "
              f"recorded one; largest gap on the way {1000 * gap.max():.1f} mm")
    if args.png:
        from host_sim.figures.runs import save_recording

        with writing("--png", args.png):
            picture = save_recording(args.png, rec, params, world, replayed=result)
        print(f"  picture: {picture}")
    return 0


def print_notes(rec: Any) -> None:
    """What loading's checks found and mended in the recording (host_sim/recordings/checks.py)."""
    for note in rec.notes:
        print(f"  note: {note.text}")


def _replay(args: argparse.Namespace, rec: Any, params: Any, world: Any) -> tuple[Any, str]:
    """(the replay, where it ran): in the world from the tracked pose, or the drive alone in an empty world."""
    from host_sim.recordings.replay import ReplayError, replay, replay_drive

    substeps = args.substeps or int(rec.meta.get("substeps") or 8)  # type: ignore[call-overload]
    tracked = rec.tracked(args.start)
    if args.world and not tracked:
        raise CliError(f"--world {args.world}: the recording has no tracker pose at row {args.start} to place "
                       f"the robot in it; without --world the drive alone is replayed")
    try:
        if world is not None and tracked:
            return replay(rec, params, world, start=args.start, substeps=substeps), f"in {world.name}"
        return (replay_drive(rec, params, start=args.start, substeps=substeps),
                "in an empty world (no world known: the drive alone)")
    except ReplayError as exc:
        raise CliError(f"{args.recording}: {exc}") from None


def _ticks(gap: Any) -> str:
    return f"{int(gap[0]):+d}/{int(gap[1]):+d}"

