"""Blind cases: a drawn robot, a random effect, magnitude, world, start and drive, recorded on the plant.

    rec_path, key_path = make_case(seed, out_dir)

Everything is drawn from the seed, and the seed's split (tuning or final) says which kinds may be drawn; the
sidecar holds the datasheet robot, the answer key (the drawn truth) is written apart.  docs/proving-ground.md.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from host_sim.loops.excitation import ExcitedController
from host_sim.controller.sil import SilController
from host_sim.physics.world import BUILTIN_NAMES, World, builtin_world
from tools.reference_plant import effects
from tools.reference_plant.drive_commands import DriveCommands, with_drive
from tools.reference_plant.recorder import record
from tools.reference_plant.robot_draw import draw_robot
from tools.reference_plant.robot_model import PlantSpec, datasheet_spec, nominal_spec

CONTROL_SHARE = 0.15  # fraction of cases with no effect at all
START_MARGIN = 0.15  # m from C to any wall at the start
# Decision rules are set on the tuning split only; the final split's seeds and its held-back kinds score them.
TUNING_SEEDS = range(0, 10_000)
FINAL_FIRST_SEED = 100_000
HELD_BACK = ("cable_drag", "encoder_drift", "weakening_motor")  # kinds drawn on the final split only
SPLITS = ("tuning", "final")
# "drawn": the case's own robot (robot_draw.py), what `bench diagnose` scores.  "datasheet": the datasheet robot
# with none of the physics the twin lacks and the paper's IR law, for tests of the diagnosis's pipeline rather
# than of its score (tests/test_diagnosis.py::test_a_blind_pair_is_named_in_full_on_the_reference_plant).
ROBOTS = ("drawn", "datasheet")


def split_of(seed: int) -> str:
    """The split a case seed belongs to: tuning (0..9999) or final (100000 and up); ValueError between."""
    if seed in TUNING_SEEDS:
        return "tuning"
    if seed >= FINAL_FIRST_SEED:
        return "final"
    raise ValueError(f"case seed {seed} is in neither split (tuning: 0..9999, final: {FINAL_FIRST_SEED} and up)")


def first_seed(split: str, offset: int = 0) -> int:
    """The `offset`-th seed of a split."""
    return offset if split == "tuning" else FINAL_FIRST_SEED + offset


def kinds(split: str, drive: str = "current") -> list[str]:
    """The effect kinds a split draws from for a case of `drive`: the final split holds every kind, tuning all
    but HELD_BACK; each kind only on the drives it belongs to (a current drive has no deadband)."""
    return [name for name, e in effects.EFFECTS.items()
            if (split == "final" or name not in HELD_BACK) and drive in e.drives]


def truth_file(key_dir: str | Path, name: str) -> Path:
    """Where make_case keeps what only the plant knows of case `name`, beside its answer key."""
    return Path(key_dir) / f"{name}.truth.npz"


def _start(world: World, rng: np.random.Generator) -> tuple[float, float, float]:
    res = 0.05
    reachable = world.free_cells(res, reachable=True)  # where the robot can go from the world's start
    clear = reachable & world.free_cells(res, START_MARGIN)
    iy, ix = np.nonzero(clear if clear.any() else reachable)
    k = int(rng.integers(len(iy)))
    xs, ys = world.cell_centres(res)
    return float(xs[ix[k]]), float(ys[iy[k]]), float(rng.uniform(-math.pi, math.pi))


def draw_effect(rng: np.random.Generator, spec: PlantSpec | None = None, split: str = "tuning",
                drive: str = "current") -> tuple[PlantSpec, list[dict[str, object]]]:
    """A plant spec (the drawn robot `spec`) with at most one concealed effect of the split's kinds, and its
    description for the answer key."""
    spec = spec if spec is not None else nominal_spec()
    if rng.random() < CONTROL_SHARE:
        return spec, []
    pool = kinds(split, drive)
    return _conceal(spec, effects.EFFECTS[pool[int(rng.integers(len(pool)))]], rng)


def draw_more(spec: PlantSpec, concealed: list[dict[str, object]], seed: int, count: int,
              drive: str = "current") -> tuple[PlantSpec, list[dict[str, object]]]:
    """spec and its key entries with in-library effects added until `count` are concealed, each of a name not
    yet concealed, drawn from its own stream.  Controls and out-of-library cases stay as they are: the
    first is the absence of any effect, the second a mismatch the library must not explain away."""
    if not concealed or not all(e["in_library"] for e in concealed):
        return spec, concealed
    concealed = list(concealed)
    while len(concealed) < count:
        rng = np.random.default_rng([seed, 2024, len(concealed)])
        taken = {e["name"] for e in concealed}
        pool = [e for e in effects.EFFECTS.values() if e.in_library and e.name not in taken and drive in e.drives]
        spec, entry = _conceal(spec, pool[int(rng.integers(len(pool)))], rng)
        concealed += entry
    return spec, concealed


def _conceal(spec: PlantSpec, effect: effects.Effect,
             rng: np.random.Generator) -> tuple[PlantSpec, list[dict[str, object]]]:
    """spec with `effect` at a drawn site and value (about the robot's own drawn value), and its key entry:
    the true value, the robot's drawn value without the effect, and the datasheet's (absent)."""
    sites = effect.sites()
    where = sites[int(rng.integers(len(sites)))]
    value = effect.draw(rng)
    spec, true, drawn = effects.apply_to_robot(spec, effect.name, value, where)
    entry: dict[str, object] = {"name": effect.name, "in_library": effect.in_library,
                                "params": {effect.param: {"value": float(np.mean(true)), "unit": effect.unit,
                                                          "absent": effect.absent, "drawn": float(np.mean(drawn)),
                                                          "at_sites": true}}}
    if effect.applies_to in ("wheel", "one wheel"):
        entry["wheel"] = where
    elif effect.applies_to == "sensor":
        entry["sensor"] = where
    extra = _placed(effect.name, spec, rng)
    if extra:
        spec = spec.replace(**{k: v["value"] for k, v in extra.items()})
        entry["params"].update(extra)  # type: ignore[attr-defined]
    return spec, [entry]


def _placed(name: str, spec: PlantSpec, rng: np.random.Generator) -> dict[str, dict[str, object]]:
    """What an out-of-library kind needs beside its size: the slope's direction, the motor's time (a share of
    the run, scaled by make_case), the tether's anchor (set to the start by make_case)."""
    if name == "floor_slope":
        return {"floor_tilt_direction": {"value": float(rng.uniform(-math.pi, math.pi)), "unit": "rad"}}
    if name == "weakening_motor":
        return {"weak_time": {"value": float(rng.uniform(0.3, 0.7)), "unit": "share of the run"}}
    return {}


def case_rng(seed: int) -> np.random.Generator:
    """The one random stream a case is drawn from."""
    return np.random.default_rng([seed, 2024])


def concealed_names(seed: int, n_effects: int = 1, drive: str = "current") -> list[str]:
    """The effects case `seed` will conceal, without recording it (for composing a suite)."""
    drawn = draw_effect(case_rng(seed), draw_robot(seed), split_of(seed), drive)
    return [str(e["name"]) for e in draw_more(*drawn, seed, n_effects, drive)[1]]


def _pick_drive(rng: np.random.Generator) -> tuple[object, dict[str, object]]:
    if rng.random() < 0.5:
        rules = int(rng.integers(2))
        return SilController(rules), {"kind": "firmware", "rule_set": rules}
    # the identification manoeuvre (twinbot sim --excite / serial --excite) through the firmware
    rules = int(rng.integers(2))
    return ExcitedController(SilController(rules)), {"kind": "manoeuvre", "rule_set": rules}


def _set_in_run(spec: PlantSpec, concealed: list[dict[str, object]], start: tuple[float, float, float],
                duration: float) -> PlantSpec:
    """The parts of an out-of-library kind fixed by the run: the weakening's time, the tether's anchor."""
    for e in concealed:
        params = e["params"]
        if e["name"] == "weakening_motor":
            params["weak_time"]["value"] *= duration  # type: ignore[index]
            params["weak_time"]["unit"] = "s"  # type: ignore[index]
            spec = spec.replace(weak_time=params["weak_time"]["value"])  # type: ignore[index]
        if e["name"] == "cable_drag":
            params["cable_anchor"] = {"value": [start[0], start[1]], "unit": "m"}  # type: ignore[index]
            spec = spec.replace(cable_anchor=(start[0], start[1]))
    return spec


def case_robot(seed: int, robot: str = "drawn") -> PlantSpec:
    """The robot case `seed` is recorded on: its own drawn one, or the datasheet's (ROBOTS)."""
    if robot not in ROBOTS:
        raise ValueError(f"robot {robot!r} is not one of {', '.join(ROBOTS)}")
    return draw_robot(seed) if robot == "drawn" else datasheet_spec(paper_ir=True)


def make_case(seed: int, out_dir: str | Path, duration: float = 90.0, key_dir: str | Path | None = None,
              n_effects: int = 1, robot: str = "drawn", drive: str = "current") -> tuple[Path, Path]:
    """Record one blind case (an in-library one concealing `n_effects` effects) on `robot` (ROBOTS) with
    `drive` (drive_commands.DRIVES); returns (recording path, answer key path).  The effect, world, start and
    excitation do not depend on `robot`."""
    rng = case_rng(seed)
    spec = with_drive(case_robot(seed, robot), drive, seed)
    spec, concealed = draw_more(*draw_effect(rng, spec, split_of(seed), drive), seed, n_effects, drive)
    world = builtin_world(BUILTIN_NAMES[int(rng.integers(len(BUILTIN_NAMES)))])
    start = _start(world, rng)
    controller, how = _pick_drive(rng)
    if drive != "current":
        controller, how = DriveCommands(controller, drive), {**how, "drive": drive}
    spec = _set_in_run(spec, concealed, start, duration)
    out_dir = Path(out_dir)
    key_dir = Path(key_dir) if key_dir is not None else out_dir / "answer_keys"
    out_dir.mkdir(parents=True, exist_ok=True)
    key_dir.mkdir(parents=True, exist_ok=True)
    name = f"case_{seed:04d}"
    rec_path = out_dir / f"{name}.csv"
    truth = record(rec_path, spec, world, controller, duration, seed=seed, pose=start)
    np.savez_compressed(truth_file(key_dir, name), encoders=np.array(truth.encoders))
    key = {"case": name, "seed": seed, "split": split_of(seed), "robot": robot, "recording": rec_path.name,
           "world": world.name, "start": start, "excitation": how, "duration": duration,
           "verdict_expected": _expected(concealed), "effects": concealed, "plant": _jsonable(dataclasses.asdict(spec))}
    key_path = key_dir / f"{name}.answer.json"
    key_path.write_text(json.dumps(key, indent=1) + "\n")
    return rec_path, key_path


def _expected(concealed: list[dict[str, object]]) -> str:
    if not concealed:
        return "match"
    return "explained" if all(e["in_library"] for e in concealed) else "unexplained"


def _jsonable(value: object) -> object:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value
