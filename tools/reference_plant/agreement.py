"""How closely the twin replays a recording of the plant: the datasheet plant (the twin's robot), or a drawn one.

`python -m tools.reference_plant.agreement`: records the plant, replays it through the twin in windows from
the recorded state (host_sim.recordings.replay) away from the walls, and prints the tick, position and heading
errors.  docs/proving-ground.md, "With no effect on, the twin replays the plant".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from host_sim.physics.params import DEFAULT, RobotParams
from host_sim.recordings.recording import Recording
from host_sim.recordings.replay import replay
from host_sim.physics.world import World


@dataclass
class Agreement:
    windows: int  # windows compared (away from walls)
    tick_rms: float  # ticks per control period, RMS over wheels and periods
    tick_p95: float  # 95th percentile of |tick error| per period
    speed_rel_rms: float  # RMS tick error / RMS recorded ticks per period (moving periods)
    pos_err_median: float  # m at the window's end
    pos_err_p95: float  # m
    head_err_median: float  # rad at the window's end
    head_err_p95: float  # rad

    def lines(self) -> list[str]:
        return [f"windows compared: {self.windows}",
                f"encoder ticks per 40 ms period: RMS error {self.tick_rms:.2f}, p95 {self.tick_p95:.1f} "
                f"({100 * self.speed_rel_rms:.1f} % of the RMS increment)",
                f"position at window end: median {1000 * self.pos_err_median:.1f} mm, "
                f"p95 {1000 * self.pos_err_p95:.1f} mm",
                f"heading at window end: median {np.degrees(self.head_err_median):.2f} deg, "
                f"p95 {np.degrees(self.head_err_p95):.2f} deg"]


def clear_rows(rec: Recording, world: World, clearance: float, p: RobotParams = DEFAULT) -> np.ndarray:
    """Rows whose tracked C is farther than body_radius + clearance from every wall."""
    assert rec.pose is not None
    dist = world.nearest_wall(rec.pose[:, :2])[0]
    return np.asarray(dist) > p.body_radius + clearance


def compare(rec: Recording, world: World, window_s: float = 1.0, clearance: float = 0.03,
            p: RobotParams = DEFAULT, stride: int | None = None) -> Agreement:
    period = rec.sample_period
    n = int(round(window_s / period))
    stride = stride or n
    clear = clear_rows(rec, world, clearance, p)
    tick_err, ticks, pos_err, head_err = [], [], [], []
    for k in range(1, len(rec) - n, stride):
        if not clear[k:k + n + 1].all():
            continue
        res = replay(rec, p, world, start=k, stop=k + n + 1)
        d_twin = np.diff(res.enc, axis=0)
        d_rec = np.diff(rec.enc[k:k + n + 1], axis=0)
        tick_err.append(d_twin - d_rec)
        ticks.append(d_rec)
        pos_err.append(float(np.hypot(*(res.pose[-1, :2] - rec.pose[k + n, :2]))))  # type: ignore[index]
        head_err.append(abs(float(res.pose[-1, 2] - rec.pose[k + n, 2])))  # type: ignore[index]
    if not tick_err:
        raise ValueError("no window away from the walls to compare")
    e = np.concatenate(tick_err).astype(float)
    r = np.concatenate(ticks).astype(float)
    moving = np.abs(r) > 0
    return Agreement(
        windows=len(pos_err), tick_rms=float(np.sqrt(np.mean(e ** 2))),
        tick_p95=float(np.percentile(np.abs(e), 95)),
        speed_rel_rms=float(np.sqrt(np.mean(e[moving] ** 2)) / np.sqrt(np.mean(r[moving] ** 2))),
        pos_err_median=float(np.median(pos_err)), pos_err_p95=float(np.percentile(pos_err, 95)),
        head_err_median=float(np.median(head_err)), head_err_p95=float(np.percentile(head_err, 95)))


def main(argv: list[str] | None = None) -> int:
    """python -m tools.reference_plant.agreement: record the nominal plant, replay it in the twin, print the figures."""
    import argparse
    import tempfile
    from pathlib import Path

    from host_sim.recordings.recording import load_recording
    from host_sim.controller.sil import SilController
    from host_sim.physics.world import WorldError, world_by_name_or_path
    from tools.reference_plant import excitation
    from tools.reference_plant.recorder import ProgramController, record
    from tools.reference_plant.robot_draw import draw_robot
    from tools.reference_plant.robot_model import datasheet_spec

    ap = argparse.ArgumentParser(prog="python -m tools.reference_plant.agreement", description=main.__doc__)
    ap.add_argument("--world", default="paper_room")
    ap.add_argument("--controller", choices=("firmware", "program"), default="firmware")
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--window", type=float, default=1.0, help="window length (s)")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--exact-tracker", action="store_true", help="no tracker noise (the model's own agreement)")
    ap.add_argument("--drawn", type=int, metavar="SEED",
                    help="record case SEED's drawn robot (robot_draw.py: parameters a few per cent off, the physics "
                         "the twin lacks) instead of the datasheet plant")
    ap.add_argument("--twin-floor", action="store_true",
                    help="record the twin itself instead of the plant (exact tracker): what the replay method "
                         "costs by itself (encoder quantisation, speeds estimated from ticks)")
    args = ap.parse_args(argv)
    try:
        world = world_by_name_or_path(args.world)
    except WorldError as exc:
        print(f"--world: {exc}")
        return 2
    spec = datasheet_spec() if args.drawn is None else draw_robot(args.drawn)
    if args.exact_tracker:
        spec = spec.replace(tracker_noise_xy=0.0, tracker_noise_phi=0.0)
    controller: object = (SilController(1) if args.controller == "firmware" else
                          ProgramController(excitation.program(np.random.default_rng(args.seed), args.duration),
                                            guard=150))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plant.csv"
        if args.twin_floor:
            _record_twin(path, world, controller, args.duration, args.seed)
        else:
            record(path, spec, world, controller, args.duration, seed=args.seed)
        result = compare(load_recording(path), world, args.window)
    what = ("the twin itself" if args.twin_floor else "the datasheet plant" if args.drawn is None
            else f"the robot drawn for case {args.drawn}")
    tracker = "exact" if args.exact_tracker or args.twin_floor else "noisy"
    print(f"{args.controller} on {what}, {world.name}, {args.duration:g} s, {tracker} tracker; "
          f"twin replay in {args.window:g} s windows:")
    print("\n".join("  " + line for line in result.lines()))
    return 0


def _record_twin(path: object, world: World, controller: object, duration: float, seed: int) -> None:
    """The twin's own run written as a robot's recording (speeds at window starts come from the encoders)."""
    from host_sim.recordings.recording import RecordingWriter
    from host_sim.loops.simulation import Simulation

    with RecordingWriter(path, source="robot", sample_period=0.04, robot=DEFAULT.to_json(),  # type: ignore[arg-type]
                         world=world.to_dict()) as writer:
        Simulation(world, DEFAULT, controller, seed=seed, recorder=writer).run_fixed(duration)


if __name__ == "__main__":
    raise SystemExit(main())
