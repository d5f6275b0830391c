"""`twinbot gui`: the paper's application (its §4, Fig. 14) in a window: the command's arguments.

Builds the GUI's settings from the command line and runs the window
(tools/gui/), interactive or headless (--frames N).  See docs/gui.md.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import float_range, input_file, int_range, non_negative_int, output_file, output_folder
from tools.arguments import CliError

MAX_SPEED = 64.0  # x real time: beyond, a frame's catch-up is whole seconds of two firmwares
MAX_FRAMES = 10_000_000
IMAGE_SUFFIXES = (".png", ".bmp", ".tga", ".jpg", ".jpeg")  # what pygame.image.save writes


def screenshot_file(text: str) -> str:
    output_file(text)
    if Path(text).suffix.lower() not in IMAGE_SUFFIXES:
        raise argparse.ArgumentTypeError(f"{text}: pygame writes {', '.join(IMAGE_SUFFIXES)}")
    return text


def window_size(text: str) -> tuple[int, int]:
    """WIDTHxHEIGHT in pixels, at least the window's minimum."""
    from tools.gui.app import MIN_SIZE

    w, _, h = text.lower().partition("x")
    if not (w.isdigit() and h.isdigit()):
        raise argparse.ArgumentTypeError(f"{text!r}: give WIDTHxHEIGHT in pixels, e.g. 1280x720")
    if int(w) < MIN_SIZE[0] or int(h) < MIN_SIZE[1] or int(w) > 16384 or int(h) > 16384:
        raise argparse.ArgumentTypeError(f"{text!r}: from {MIN_SIZE[0]}x{MIN_SIZE[1]} to 16384x16384")
    return int(w), int(h)


def existing_folder(text: str) -> str:
    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no such folder")
    return output_folder(text)


DESCRIPTION = """\
Draw the room with the mouse (walls snap to a grid; select, move, delete,
undo; save and load world files; zoom and pan), and watch three robots at
once: the simulated robot running the firmware in the loop (SIL), the user
robot driven by the arrow keys or a joystick / gamepad, and, with --port,
the real robot on a serial port (a Pico, or a virtual board's pty from
`twinbot board`), its pose from its odometry and its IR readings as they
arrive, and its ghost: where the late-signal twin says it is now, its
signal being late (--link-floor; `twinbot board --late MS` to try it).
The user's orders can drive the simulated and the real robot too.
The replay panel (--replay FILE, or e in the window) scrubs a recording
with a time slider over plots of its IR readings, wheel speeds and
commands, and d diagnoses it in the background (as `twinbot diagnose`).
Press h in the window for every key.

Headless: --frames N runs N frames of 1/60 s without a display
(SDL_VIDEODRIVER=dummy) and --screenshot writes the last one.  The frame
time is measured by `twinbot bench gui`.
"""

EXAMPLES = """\
examples:
  twinbot gui                                   # the paper's room, refined rules
  twinbot gui --world maze --rules first --speed 4
  twinbot gui --world my_room.json --port /dev/pts/3
  twinbot gui --frames 300 --screenshot gui.png # headless: 5 s of the run, one picture
  twinbot gui --replay run.csv                  # scrub a recording; d diagnoses it
  twinbot bench gui                             # frame time with the three robots
"""


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(name, help=summary, description=DESCRIPTION, epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--world", default="paper_room", help="built-in world (paper_room, maze, arena) or a world file")
    p.add_argument("--rules", choices=("first", "refined"), default="refined", help="fuzzy rule set (default refined)")
    p.add_argument("--port", help="the real robot's serial port (or a virtual board's pty); absent without it")
    p.add_argument("--link-floor", type=float_range(0, 10_000, unit="ms"), default=0.0, metavar="MS",
                   help="the real robot's link: its fastest delivery in ms (a serial frame's transmit time, or half "
                        "a round trip); the ghost adds it to the lateness it measures (default 0: lateness above "
                        "the fastest frame)")
    p.add_argument("--pil", action="store_true",
                   help="the simulated robot's firmware on a virtual board under MicroPython (processor in the loop)")
    p.add_argument("--speed", type=float_range(0, MAX_SPEED, lo_open=True), default=1.0,
                   help=f"k x real time, > 0 and <= {MAX_SPEED:g} (default 1)")
    p.add_argument("--realtime", action="store_true", help="the step from the clock (the paper's Dt); default fixed")
    p.add_argument("--no-noise", action="store_true", help="noise-free sensors")
    p.add_argument("--emitter", type=int_range(0, 100, unit="%"), default=60,
                   help="IR emitter power L, 0..100 %% (default 60)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the sensor noise, >= 0 (default 0)")
    p.add_argument("--params", metavar="FILE", help="robot parameters JSON (any subset; see host_sim/physics/params.py)")
    p.add_argument("--save", metavar="FILE", type=output_file,
                   help="the world file that s saves and l loads (default: --world if a file, else NAME.json)")
    p.add_argument("--out", metavar="DIR", type=existing_folder, default=".",
                   help="folder for recordings and screenshots (default .)")
    p.add_argument("--size", type=window_size, default=None, metavar="WxH",
                   help="the window's size in pixels at start (default 1280x720; the window can be resized)")
    p.add_argument("--replay", metavar="REC.csv", type=input_file,
                   help="a recording (with its sidecar) to show in the replay panel at start (docs/recordings.md)")
    p.add_argument("--frames", type=int_range(1, MAX_FRAMES), help="headless: run this many frames of 1/60 s, then stop")
    p.add_argument("--screenshot", metavar="FILE", type=screenshot_file,
                   help="with --frames: write the last frame (.png, .bmp, .tga, .jpg)")
    p.set_defaults(func=run)


def settings_from(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from host_sim.physics.world import BUILTIN_NAMES
    from tools.gui.app import Settings
    from tools.cli.sim import load_inputs

    params, world = load_inputs(args, drives=("current",))  # its recordings write the firmware's currents in A
    if args.screenshot and args.frames is None:
        raise CliError("--screenshot needs --frames N (headless run)")
    if args.replay:
        check_recording(args.replay)
    out = Path(args.out)
    save = Path(args.save) if args.save else (Path(args.world) if args.world not in BUILTIN_NAMES
                                              else out / f"{world.name}.json")
    return Settings(world=world, params=params, rules=args.rules, port=args.port, pil=args.pil, speed=args.speed,
                    realtime=args.realtime, noise=not args.no_noise, emitter_pct=args.emitter, seed=args.seed,
                    world_file=save, out_dir=out, link_floor_s=args.link_floor / 1000.0,
                    replay=Path(args.replay) if args.replay else None, **({"size": args.size} if args.size else {}))


def check_recording(path: str) -> None:
    """--replay: a bad recording is one line and exit 2 before a window opens (in the window: a message)."""
    from host_sim.physics.params import DEFAULT
    from tools.gui.replay import load_replay

    try:
        load_replay(Path(path), DEFAULT, (0.0, 0.0, 0.0))
    except (OSError, ValueError) as exc:
        raise CliError(f"--replay: {exc}") from None


def run(args: argparse.Namespace) -> int:
    from host_sim.board.serial_link import LinkError
    from tools.gui import loop

    settings = settings_from(args)
    import pygame

    try:
        window = loop.open_window(settings, headless=args.frames is not None)
    except LinkError as exc:
        raise CliError(f"--port: {exc}") from None
    except pygame.error as exc:  # (a RuntimeError too: before the next clause)
        raise CliError(f"cannot open a window ({exc}); without a display run headless: --frames N") from None
    except RuntimeError as exc:  # the virtual board of --pil did not start
        raise CliError(f"--pil: {exc}") from None
    app = window.app
    try:
        frames = loop.run(window, args.frames)
        if args.screenshot:
            app.screenshot(args.screenshot)
            print(f"screenshot: {args.screenshot} ({frames} frames, t = {app.sim.sim.robot.t:.2f} s simulated)")
    finally:
        app.close()
        loop.close()
    return 0


__all__ = ["register", "run"]
