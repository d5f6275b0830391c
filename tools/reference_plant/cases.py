"""Blind cases: a random effect, magnitude, world, start and drive, recorded on the plant.

    rec_path, key_path = make_case(seed, out_dir)

Everything is drawn from the seed; the recording's sidecar holds the nominal robot, and the answer key
(with the plant's unrounded encoder positions beside it) is written apart.  docs/proving-ground.md, "Blind cases".
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
from tools.reference_plant.recorder import record
from tools.reference_plant.robot_model import PlantSpec, nominal_spec

CONTROL_SHARE = 0.15  # fraction of cases with no effect at all
START_MARGIN = 0.15  # m from C to any wall at the start


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


def draw_effect(rng: np.random.Generator) -> tuple[PlantSpec, list[dict[str, object]]]:
    """A plant spec with at most one concealed effect, and its description for the answer key."""
    spec = nominal_spec()
    if rng.random() < CONTROL_SHARE:
        return spec, []
    effect = list(effects.EFFECTS.values())[int(rng.integers(len(effects.EFFECTS)))]
    return _conceal(spec, effect, rng)


def draw_more(spec: PlantSpec, concealed: list[dict[str, object]], seed: int,
              count: int) -> tuple[PlantSpec, list[dict[str, object]]]:
    """spec and its key entries with in-library effects added until `count` are concealed, each of a name not
    yet concealed, drawn from its own stream.  Controls and out-of-library cases stay as they are: the
    first is the absence of any effect, the second a mismatch the library must not explain away."""
    if not concealed or not all(e["in_library"] for e in concealed):
        return spec, concealed
    concealed = list(concealed)
    while len(concealed) < count:
        rng = np.random.default_rng([seed, 2024, len(concealed)])
        taken = {e["name"] for e in concealed}
        pool = [e for e in effects.EFFECTS.values() if e.in_library and e.name not in taken]
        spec, entry = _conceal(spec, pool[int(rng.integers(len(pool)))], rng)
        concealed += entry
    return spec, concealed


def _conceal(spec: PlantSpec, effect: effects.Effect,
             rng: np.random.Generator) -> tuple[PlantSpec, list[dict[str, object]]]:
    """spec with `effect` at a drawn site and value, and its entry for the answer key."""
    sites = effect.sites()
    where = sites[int(rng.integers(len(sites)))]
    value = effect.draw(rng)
    spec = effects.apply(spec, effect.name, value, where)
    entry: dict[str, object] = {"name": effect.name, "in_library": effect.in_library,
                                "params": {effect.param: {"value": value, "unit": effect.unit,
                                                          "absent": effect.absent}}}
    if effect.applies_to == "wheel":
        entry["wheel"] = where
    elif effect.applies_to == "sensor":
        entry["sensor"] = where
    if effect.name == "floor_tilt":
        direction = float(rng.uniform(-math.pi, math.pi))
        spec = spec.replace(floor_tilt_direction=direction)
        entry["params"]["floor_tilt_direction"] = {"value": direction, "unit": "rad"}  # type: ignore[index]
    return spec, [entry]


def case_rng(seed: int) -> np.random.Generator:
    """The one random stream a case is drawn from."""
    return np.random.default_rng([seed, 2024])


def concealed_names(seed: int, n_effects: int = 1) -> list[str]:
    """The effects case `seed` will conceal, without recording it (for composing a suite)."""
    return [str(e["name"]) for e in draw_more(*draw_effect(case_rng(seed)), seed, n_effects)[1]]


def make_case(seed: int, out_dir: str | Path, duration: float = 90.0,
              key_dir: str | Path | None = None, n_effects: int = 1) -> tuple[Path, Path]:
    """Record one blind case (an in-library one concealing `n_effects` effects); returns (recording path,
    answer key path)."""
    rng = case_rng(seed)
    spec, concealed = draw_more(*draw_effect(rng), seed, n_effects)
    world = builtin_world(BUILTIN_NAMES[int(rng.integers(len(BUILTIN_NAMES)))])
    start = _start(world, rng)
    if rng.random() < 0.5:
        rules = int(rng.integers(2))
        controller: object = SilController(rules)
        how = {"kind": "firmware", "rule_set": rules}
    else:  # the identification manoeuvre (twinbot sim --excite / serial --excite) through the firmware
        rules = int(rng.integers(2))
        controller = ExcitedController(SilController(rules))
        how = {"kind": "manoeuvre", "rule_set": rules}
    out_dir = Path(out_dir)
    key_dir = Path(key_dir) if key_dir is not None else out_dir / "answer_keys"
    out_dir.mkdir(parents=True, exist_ok=True)
    key_dir.mkdir(parents=True, exist_ok=True)
    name = f"case_{seed:04d}"
    rec_path = out_dir / f"{name}.csv"
    truth = record(rec_path, spec, world, controller, duration, seed=seed, pose=start)
    np.savez_compressed(truth_file(key_dir, name), encoders=np.array(truth.encoders))
    key = {"case": name, "seed": seed, "recording": rec_path.name, "world": world.name, "start": start,
           "excitation": how, "duration": duration, "verdict_expected": _expected(concealed),
           "effects": concealed, "plant": _jsonable(dataclasses.asdict(spec))}
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
