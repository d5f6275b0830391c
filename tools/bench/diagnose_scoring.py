"""The scorer of `twinbot bench diagnose`: the only code that reads the answer keys.

`score_case` puts a diagnosis's JSON document beside the key of its case: named right (first k effects,
right site), parameter error in the library's terms (PARAMS), false alarms, out-of-library calls, effects
the recording cannot show (`not_excited`), and the wheel fit against a perfect twin (`perfect_twin_fit`).
`score_sindy` judges the SINDy baseline the same way.  The rules: docs/proving-ground.md, "The scorer".
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from host_sim.diagnosis.model_error import needed_share
from host_sim.physics import effects as library
from host_sim.physics.params import RobotParams
from host_sim.recordings.recording import Recording
from host_sim.physics.world import world_from_dict
from tools.reference_plant import effects as plant_effects
from tools.reference_plant.cases import truth_file
from tools.reference_plant.robot_model import CASTER_X

G = 9.81
DRIVE_CHANNELS = ("wheel_l", "wheel_r", "forward", "lateral", "heading_rate", "travel", "turn")
PARAM_TOLERANCE = 0.15  # relative parameter error counted as right (the parameter target)
MIN_EXCITED_SHARE = 0.01  # an effect shown in fewer than 1 % of the periods is "not excited"
TRACTION_MARGIN = 0.8  # demand within 80 % of mu N may already slip: weight shifts as the robot accelerates
WALL_SEEN_COUNTS = 50  # reflected counts (on - off) from which an IR pair "sees a wall"
LEAK_SEEN_COUNTS = 3.0  # counts (one reading's noise) the leaked ambient must vary by to differ from an offset
WALL_TOUCH_MARGIN = 0.005  # m beyond the body's radius: within it, the robot touches a wall
WALL_BLOCK_S = 1.0  # diagnosis judges the drive in windows of 1 s clear of the walls: blocks of that length
AMBIENT_SMOOTH_S = 0.5  # the ambient light is judged on a running mean: the readings' own noise is not light


@dataclass(frozen=True)
class ParamMap:
    """How the plant's true value of an effect reads in the library's terms."""

    plant_param: str  # the key's parameter (the plant's true physical value)
    library_param: str  # the library effect's parameter (host_sim/physics/effects.py)
    conversion: str  # "same" | "minus nominal" | "caster load" | "scrub load"
    relative_to: str  # the error's denominator: "change" |true - absent| or "value" |true|


# How each plant effect's true value reads in the library's terms, derived from the two libraries by name
# (tools/reference_plant/effects.py, host_sim/physics/effects.py):
#   same:          the library parameter is the same physical quantity (the default)
#   minus nominal: the library holds a delta added to a nominal RobotParams field (true - nominal)
#   caster load:   the library holds the caster's drag FORCE (N): mu_caster x the caster's normal load,
#                  N_c = m_body g d / CASTER_X (moments about the axle, level floor; d = com_offset)
#   scrub load:    the library holds the scrub TORQUE (N m): the plant's torsional friction (m) x the
#                  tyres' normal load, (m_body + 2 m_wheel) g - N_c (MuJoCo: torque = mu_torsional N per contact)
#   wheel load:    the library's mu grips with the whole weight (the twin's wheels carry it all): the
#                  plant's tyre friction x the tyres' share of the weight, ((m_body + 2 m_wheel) g - N_c) / that
# The error is |fitted - true| / denominator:
#   change: |true - absent|, the size of the effect (a fit that stays at nominal scores 100 %) (the default)
#   value:  |true|, for limits whose absent value is "no limit in practice" (0.5 A, mu = 1)
CONVERSIONS = {"caster_drag": "caster load", "turning_resistance": "scrub load", "traction_limit": "wheel load"}
RELATIVE_TO_VALUE = ("current_limit", "traction_limit")


def _param_map(name: str) -> ParamMap:
    prm = library.LIBRARY[name].params[0]
    conversion = CONVERSIONS.get(name, "minus nominal" if prm.admits.added_to else "same")
    return ParamMap(plant_effects.EFFECTS[name].param, prm.name, conversion,
                    "value" if name in RELATIVE_TO_VALUE else "change")


PARAMS: dict[str, ParamMap] = {name: _param_map(name) for name, e in plant_effects.EFFECTS.items() if e.in_library}


def load_key(path: str | Path) -> dict[str, Any]:
    """The answer key, with the plant's unrounded encoder positions (n, 2) as "encoders" where
    cases.make_case kept them beside it (a suite kept without its truth files has none)."""
    key: dict[str, Any] = json.loads(Path(path).read_text())
    truth = truth_file(Path(path).parent, Path(path).name.removesuffix(".answer.json"))
    if truth.exists():
        with np.load(truth) as data:
            key["encoders"] = data["encoders"]
    return key


def perfect_twin_fit(exact: np.ndarray, rec: Recording, judged: list[list[float]]) -> float | None:
    """The worse wheel's fit % (channels.fit_percent, as diagnosis judges it) of a twin that knows each
    encoder's true unrounded position: the plant's own, `exact` (n, 2) ticks at each row, in the windows
    `judged` ([t0, t1] of each: the diagnosis JSON's fit.judged).  None without windows."""
    from host_sim.diagnosis.channels import fit_percent

    rows = [np.arange(int(np.searchsorted(rec.t, t0 - 1e-6)), int(np.searchsorted(rec.t, t1 + 1e-6)))
            for t0, t1 in judged]
    if not rows:
        return None
    fits = []
    for w in range(2):
        y = np.concatenate([np.diff(rec.enc[r, w]).astype(float) for r in rows])
        y_hat = np.concatenate([np.diff(exact[r, w]) for r in rows])
        fits.append(fit_percent(y, y_hat))
    return float(min(fits))


def _nominal_field(nominal: RobotParams, library_name: str) -> float:
    """The nominal RobotParams value a "minus nominal" delta is taken from (dry_friction -> coulomb_friction)."""
    field = library.LIBRARY[library_name].params[0].admits.added_to
    assert field is not None, f"{library_name} is no delta from a nominal field"
    return float(getattr(nominal, field))


def caster_load(plant: dict[str, Any]) -> float:
    """N on the caster ball: the body's weight at G, d ahead of the axle, against the caster CASTER_X ahead."""
    return float(plant["body_mass"]) * G * max(float(plant["com_offset"]), 0.0) / CASTER_X


def _in_library_terms(name: str, v: float, plant: dict[str, Any], nominal: RobotParams) -> float:
    """A plant value of effect `name` as the library's parameter (PARAMS' conversion)."""
    row = PARAMS[name]
    if row.conversion == "minus nominal":
        return v - _nominal_field(nominal, name)
    if row.conversion == "caster load":  # the ball's rolling drag is a drag force of the caster too
        return (v + float(plant.get("caster_rolling", 0.0))) * caster_load(plant)
    if row.conversion in ("scrub load", "wheel load"):
        weight = (float(plant["body_mass"]) + 2 * float(plant["wheel_mass"])) * G
        return v * (weight - caster_load(plant)) / (weight if row.conversion == "wheel load" else 1.0)
    return v


def true_value(effect: dict[str, Any], plant: dict[str, Any], nominal: RobotParams) -> tuple[float, float]:
    """(true value, this robot's value without the effect) in the library's terms: the drawn robot's own
    value (the key's `drawn`), or the datasheet's where the key has none."""
    name = effect["name"]
    entry = effect["params"][PARAMS[name].plant_param]
    true = _in_library_terms(name, float(entry["value"]), plant, nominal)
    if "drawn" in entry:
        return true, _in_library_terms(name, float(entry["drawn"]), plant, nominal)
    return true, float(library.absent_values(nominal, name)[0])


def parameter_error(effect: dict[str, Any], plant: dict[str, Any], nominal: RobotParams,
                    fitted: float, ci95: list[float] | None = None,
                    ci95_fit: list[float] | None = None) -> dict[str, Any]:
    """|fitted - true| over the effect's size on this robot (|true - its own value without it|), or over
    |true| for the limits; `covered`: the reported 95 % interval holds the true value (None without one),
    `covered_fit`: the fit's own interval does; `share_needed`: the share of the effect's size the model
    error would have to add to the fit's interval to hold it (model_error.needed_share, whose 95 % conformal
    quantile over the tuning split is model_error.MODEL_ERROR)."""
    true, absent = true_value(effect, plant, nominal)
    denom = abs(true - absent) if PARAMS[effect["name"]].relative_to == "change" else abs(true)
    fit_ci = ci95_fit or ci95  # a diagnosis kept before the model error was added reported the fit's alone
    out = {"true": true, "fitted": fitted, "absent": absent, "covered": _holds(ci95, true),
           "covered_fit": _holds(fit_ci, true), "error": abs(fitted - true) / denom if denom > 0 else math.inf}
    if fit_ci and len(fit_ci) == 2:
        out["share_needed"] = needed_share(effect["name"], fitted,
                                           (float(fit_ci[0]), float(fit_ci[1])), true, nominal)
    return out


def _holds(ci: list[float] | None, true: float) -> bool | None:
    return None if not ci or len(ci) != 2 else bool(float(ci[0]) <= true <= float(ci[1]))


def _site(entry: dict[str, Any]) -> str | int | None:
    return entry.get("wheel", entry.get("sensor"))


# --------------------------------------------------------------------------- #
# Not excited: the recording cannot show the effect
# --------------------------------------------------------------------------- #
def not_excited(effect: dict[str, Any], plant: dict[str, Any], rec: Recording) -> str | None:
    """Why this recording cannot show the effect, or None when it can."""
    name = effect["name"]
    value = float(next(iter(effect["params"].values()))["value"])
    if name == "current_limit":
        shown = (np.abs(rec.cmd) > value).any(axis=1)
        share, where = _shown_clear_of_walls(shown, plant, rec)
        if share < MIN_EXCITED_SHARE:
            return (f"the references exceed the {1000 * value:.0f} mA limit in {100 * share:.1f} % of the "
                    f"periods{where}")
    elif name == "traction_limit":
        shown = np.asarray((traction_demand(plant, rec) > TRACTION_MARGIN * value * wheel_load(plant)).any(axis=1))
        share, where = _shown_clear_of_walls(shown, plant, rec)
        if share < MIN_EXCITED_SHARE:
            return (f"the drive can ask more than {100 * TRACTION_MARGIN:.0f} % of the grip (mu = {value:.2f}) "
                    f"in {100 * share:.1f} % of the periods{where}")
    elif name == "adc_clipping":  # the plant's readings stop at the clip's whole counts: none there, none clipped
        top = math.floor(value)  # the plant truncates its clipped reading (plant.Plant.read_ir)
        clipped = ((rec.ir_on >= top) | (rec.ir_amb >= top)).any(axis=1)
        if clipped.mean() < MIN_EXCITED_SHARE:
            return f"a reading reaches the {value:.0f}-count clip in {100 * clipped.mean():.1f} % of the periods"
    elif name in ("ir_gain", "ir_misalignment", "ir_latency"):
        sensors = [int(effect["sensor"])] if "sensor" in effect else list(range(8))
        seen = ((rec.ir_on - rec.ir_amb)[:, sensors] > WALL_SEEN_COUNTS).any(axis=1)
        if seen.mean() < MIN_EXCITED_SHARE:
            which = f"sensor {sensors[0]}" if len(sensors) == 1 else "no sensor"
            return f"{which} sees a wall (> {WALL_SEEN_COUNTS} counts) in {100 * seen.mean():.1f} % of the periods"
    elif name == "ambient_leakage":
        k = int(effect["sensor"])
        width = max(1, int(round(AMBIENT_SMOOTH_S / rec.sample_period)))
        light = np.convolve(rec.ir_amb[:, k].astype(float), np.ones(width) / width, mode="valid")
        swing = abs(value) * float(np.percentile(light, 95) - np.percentile(light, 5))
        if swing < LEAK_SEEN_COUNTS:
            return (f"sensor {k}'s ambient light varies so little that the leak varies by {swing:.1f} counts "
                    f"(< {LEAK_SEEN_COUNTS:.0f}): a constant, the same as an ir_offset")
    return None


def _shown_clear_of_walls(shown: np.ndarray, plant: dict[str, Any], rec: Recording) -> tuple[float, str]:
    """The share of the periods that show the effect clear of the walls, and words for the periods that
    show it only touching one ("" if none do)."""
    share = float((shown & clear_of_walls(plant, rec)).mean())
    in_all = float(shown.mean())
    if in_all < MIN_EXCITED_SHARE:  # not shown anywhere: no wall to blame
        return share, ""
    return share, (f" clear of the walls ({100 * in_all:.1f} % in all: the rest touch a wall, where "
                   f"diagnosis does not judge the drive)")


def clear_of_walls(plant: dict[str, Any], rec: Recording) -> np.ndarray:
    """(n,) bool: the period lies in a block of WALL_BLOCK_S in which the tracked robot never comes within
    WALL_TOUCH_MARGIN of a wall (all True without a tracker or walls)."""
    world = rec.meta.get("world")
    if rec.pose is None or not world:
        return np.ones(len(rec.t), dtype=bool)
    walls = world_from_dict(world, "the recording's sidecar world")
    if walls.n_walls == 0:
        return np.ones(len(rec.t), dtype=bool)
    distance = walls.nearest_wall(rec.pose[:, :2])[0]
    touching = distance < float(plant["body_radius"]) + WALL_TOUCH_MARGIN
    block = max(1, int(round(WALL_BLOCK_S / rec.sample_period)))
    blocks = np.arange(len(rec.t)) // block
    return ~np.bincount(blocks, weights=touching, minlength=blocks[-1] + 1)[blocks].astype(bool)


def wheel_load(plant: dict[str, Any]) -> float:
    """N on each tyre, level floor, at rest: the weight the caster does not carry, shared by the two wheels."""
    return 0.5 * ((float(plant["body_mass"]) + 2 * float(plant["wheel_mass"])) * G - caster_load(plant))


def traction_demand(plant: dict[str, Any], rec: Recording) -> np.ndarray:
    """(n, 2) N: the largest force each tyre could be asked for in each period.

    The motor's torque at the commanded current (within the driver's limit
    and the voltage left after back-EMF; for a bridge drive, the current its
    volts could push against a braking back-EMF), plus the wheel's own inertia
    torque (from the encoders' second difference), over the radius: an
    upper bound of the contact force, since friction only lowers it.
    """
    ticks = np.asarray(plant["ticks_per_rev"], dtype=float)
    radius = np.asarray(plant["wheel_radius"], dtype=float)
    kt = np.asarray(plant["torque_constant"], dtype=float)
    n_gear, volts = float(plant["gear_ratio"]), float(plant["battery_voltage"])
    ohm = np.asarray(plant["armature_resistance"], dtype=float)
    dt = rec.sample_period
    omega = np.gradient(rec.enc.astype(float) * 2 * np.pi / ticks, dt, axis=0)
    alpha = np.gradient(omega, dt, axis=0)
    emf = kt * n_gear * np.abs(omega)
    if rec.drive == "current":
        i = np.minimum(np.abs(rec.cmd), float(plant["current_limit"]))
    else:  # a bridge: at most the volts it applies, plus a back-EMF it brakes against, over R
        applied = {"duty": np.abs(rec.cmd) * volts, "voltage": np.abs(rec.cmd)}.get(rec.drive, volts)
        i = (applied + emf) / ohm
    i = np.minimum(i, (volts + emf) / ohm)  # braking against back-EMF allows more
    torque = float(plant["gear_efficiency"]) * n_gear * kt * i + float(plant["wheel_inertia"]) * np.abs(alpha)
    return torque / radius  # type: ignore[no-any-return]


# --------------------------------------------------------------------------- #
# One case
# --------------------------------------------------------------------------- #
def score_case(key: dict[str, Any], diagnosis: dict[str, Any] | None, rec: Recording, nominal: RobotParams,
               error: str | None = None) -> dict[str, Any]:
    """The case's score.  diagnosis: its JSON document, or None with `error` (refused, or crashed)."""
    concealed = key["effects"]
    row: dict[str, Any] = {"case": key["case"], "kind": _kind(concealed), "truth": describe_truth(key),
                           "verdict": diagnosis["verdict"] if diagnosis else error, "named": describe_named(diagnosis)}
    if diagnosis is not None:
        row["fit_before"] = _wheel_fit(diagnosis["fit"]["before"])
        row["fit_after"] = _wheel_fit(diagnosis["fit"]["after"])
        row["fit_ceiling"] = _wheel_fit(diagnosis["fit"].get("ceiling", {}))  # a twin right but for the rounding
        if "encoders" in key and "judged" in diagnosis["fit"]:
            row["fit_perfect"] = perfect_twin_fit(key["encoders"], rec, diagnosis["fit"]["judged"])
    row["not_concealed"] = not_concealed(diagnosis, concealed)
    if row["kind"] == "control":
        row["outcome"] = "right" if diagnosis and diagnosis["verdict"] == "match" else "false alarm"
        return row
    if row["kind"] == "out of library":
        row.update(_score_unlisted(diagnosis, concealed))
        reasons = [r for e in concealed if not e["in_library"] and (r := not_excited(e, key["plant"], rec))]
        if reasons and row["outcome"] == "missed":  # a match on a recording that cannot show it is no miss
            row["not_excited"] = "; ".join(reasons)
    else:
        row.update(_score_listed(concealed, key["plant"], diagnosis, nominal, rec))
    if diagnosis is None and str(error).startswith("refused"):
        row["outcome"] = "refused"  # diagnosis declined the recording (too short, too still): a miss all the same
    return row


def not_concealed(diagnosis: dict[str, Any] | None, concealed: list[dict[str, Any]]) -> list[str]:
    """The effects a diagnosis names that no concealed effect is (by name and site): on a control or beside a
    right name as much as instead of one.  A name that is wrong costs a user more than "unexplained"."""
    if diagnosis is None:
        return []
    truth = {(e["name"], _site(e)) for e in concealed if e["in_library"]}
    return [f["name"] + ("" if _site(f) is None else f"({_site(f)})") for f in diagnosis["effects"]
            if (f["name"], _site(f)) not in truth]


def _kind(concealed: list[dict[str, Any]]) -> str:
    if not concealed:
        return "control"
    return "in library" if all(e["in_library"] for e in concealed) else "out of library"


def _wheel_fit(fit: dict[str, float | None]) -> float | None:
    """The worse wheel's held-out fit %: the figure the wheel-speed target is judged on."""
    vals = [v for w in ("wheel_l", "wheel_r") if (v := fit.get(w)) is not None]
    return float(min(vals)) if len(vals) == 2 else None


def _score_listed(concealed: list[dict[str, Any]], plant: dict[str, Any], diagnosis: dict[str, Any] | None,
                  nominal: RobotParams, rec: Recording) -> dict[str, Any]:
    """A case's k concealed in-library effects against the diagnosis's first k (forward selection's
    strongest first): each is named when one of them has its name and its site, and then has a parameter
    error.  Extra effects after the first k are not judged.  The case is "right" when every effect the
    recording shows (not_excited) is named; "effects" holds each effect's score, and "not_excited" the
    reasons when the recording shows none of them."""
    scores: list[dict[str, Any]] = []
    for effect in concealed:
        score: dict[str, Any] = {"truth": describe_effect(effect), "named": False}
        reason = not_excited(effect, plant, rec)
        if reason:
            score["not_excited"] = reason
        scores.append(score)
    out: dict[str, Any] = {"effects": scores}
    if all("not_excited" in sc for sc in scores):
        out["not_excited"] = "; ".join(sc["not_excited"] for sc in scores)
    if diagnosis is None:
        out["outcome"] = "error"
        return out
    found = diagnosis["effects"]
    leading = found[:len(concealed)]
    for effect, score in zip(concealed, scores):
        match = next((f for f in leading if f["name"] == effect["name"] and _site(f) == _site(effect)), None)
        if match is not None:
            score["named"] = True
            fitted_param = match["params"][PARAMS[effect["name"]].library_param]
            score["param"] = parameter_error(effect, plant, nominal, float(fitted_param["value"]),
                                             fitted_param.get("ci95"), fitted_param.get("ci95_fit"))
    judged = [i for i, sc in enumerate(scores) if "not_excited" not in sc] or list(range(len(scores)))
    missing = [concealed[i] for i in judged if not scores[i]["named"]]
    if not missing:
        out["outcome"] = "right"
    elif not found:
        out["outcome"] = "missed" if diagnosis["verdict"] == "match" else "unexplained"
    elif len(missing) < len(judged):
        out["outcome"] = "partly named"
    elif any(f["name"] == e["name"] for f in leading for e in missing):
        out["outcome"] = "wrong side"  # its value is another wheel's, or shared: no parameter error
    else:
        out["outcome"] = "wrong name"
    return out


def _score_unlisted(diagnosis: dict[str, Any] | None, concealed: list[dict[str, Any]]) -> dict[str, Any]:
    """Right: unexplained or partly explained, located where the kind shows (the IR ring for a clipping ADC,
    the drive otherwise), and no library effect named (one given only as `closest` is no name)."""
    if diagnosis is None:
        return {"outcome": "error"}
    verdict = diagnosis["verdict"]
    where = [u["channel"] for u in diagnosis["unexplained"]] + [u["channel"] for u in diagnosis["located"]]
    shows_on = [c for c in where if _shows_on(c, concealed)]
    out: dict[str, Any] = {"located_on": sorted(set(where))}
    if diagnosis.get("closest"):
        out["closest"] = diagnosis["closest"]
    named = [e for e in diagnosis["effects"] if not e.get("closest")]
    if verdict in ("unexplained", "partly explained") and not named:
        out["outcome"] = "right" if shows_on else "wrong place"
    else:
        out["outcome"] = "missed" if verdict == "match" else "wrong name"
    return out


def _shows_on(channel: str, concealed: list[dict[str, Any]]) -> bool:
    """The channel is where an out-of-library kind shows: the IR ring for adc_clipping, the drive (and the
    encoders' counts, alone or against the tracker: odometry) for the others."""
    names = {e["name"] for e in concealed if not e["in_library"]}
    ring = channel.startswith("ir_") and "adc_clipping" in names
    drive = (channel in DRIVE_CHANNELS + ("count_l", "count_r", "odometry_l", "odometry_r")
             and bool(names - {"adc_clipping"}))
    return ring or drive


def describe_truth(key: dict[str, Any]) -> str:
    if not key["effects"]:
        return "none (control)"
    return " + ".join(describe_effect(e) for e in key["effects"])


def describe_effect(e: dict[str, Any]) -> str:
    """One concealed effect in words: its name, site and (first) true value."""
    site = _site(e)
    name, (param, p) = e["name"], next(iter(e["params"].items()))
    return f"{name}{'' if site is None else f'({site})'} {param}={p['value']:.4g} {p['unit']}"


def describe_named(diagnosis: dict[str, Any] | None) -> str:
    if diagnosis is None:
        return "-"
    names = []
    for e in diagnosis["effects"]:
        site = _site(e)
        (pname, p), = list(e["params"].items())[:1]
        names.append(f"{e['name']}{'' if site is None else f'({site})'} {pname}={p['value']:.4g}")
    return "; ".join(names) or "-"


# --------------------------------------------------------------------------- #
# SINDy: could its terms name the effect?
# --------------------------------------------------------------------------- #
# The one term a physicist would read as the effect, in the wheel's own equation
# (sindy_baseline's features: w_l, w_r wheel speeds, i_l, i_r commands, tanh of each).
# Effects without one (pose, IR, delays, limits, loads) cannot be named from a wheel residual.
SINDY_SIGNATURE = {"dry_friction": "tanh(w_{w})", "viscous_friction": "w_{w}", "encoder_scale": "w_{w}",
                   "torque_constant": "i_{w}"}


def score_sindy(key: dict[str, Any], terms: list[dict[str, Any]]) -> dict[str, Any]:
    """Named: a control with no active term; or, when every concealed effect has a signature term, exactly
    those terms active in the affected wheels' equations (each effect's in each of its wheels), no other."""
    active = [t for t in terms if t["coef"] != 0.0]
    if not key["effects"]:
        return {"named": not active, "why": "no term (right)" if not active else f"{len(active)} spurious terms"}
    expected: dict[str, set[str]] = {"l": set(), "r": set()}
    for effect in key["effects"]:
        signature = SINDY_SIGNATURE.get(effect["name"])
        if signature is None:
            return {"named": False, "why": f"no SINDy term can stand for {effect['name']}"}
        for w in {"left": ["l"], "right": ["r"]}.get(effect.get("wheel", "both"), ["l", "r"]):
            expected[w].add(signature.format(w=w))
    ok = all(sorted(t["term"] for t in active if t["equation"] == f"w_{w}") == sorted(expected[w]) for w in "lr")
    return {"named": ok, "why": "its signature terms" if ok else "not the signature terms alone"}
