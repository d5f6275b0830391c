"""Fuzzy inference speed: the firmware engine on CPython against peer libraries.

`bench_inference(repeats)` times one inference of firmware/fuzzy.py and of
the same rule base built in simpful, pyfuzzylite and scikit-fuzzy, for
`twinbot bench firmware`.  Figures: docs/benchmarks.md; the controller:
docs/fuzzy.md.
"""
from __future__ import annotations

import contextlib
import io
import platform
import statistics
import sys
import time
import warnings
from typing import Any, Callable

from firmware import fuzzy as fz
from host_sim.controller.fuzzy_rulebase import RULE_SET_NAMES, SENSOR_BEARINGS, TERM_NAMES, circular_weight, singletons

Infer = Callable[[list[int]], tuple[float, float]]
MAX_READING = 4095  # 12-bit ADC


# --------------------------------------------------------------------------- #
# The rule base, independently of the firmware's integer arithmetic
# --------------------------------------------------------------------------- #
# The peer builds live here so that tests/test_fuzzy_peer.py checks exactly the simpful build that is
# timed.  They take the circular weights from the floating-point geometry (sensor i at 45*i degrees,
# triangles of half-width 90 degrees), as min(near, weight) with a constant input ("bias"), so the
# firmware's integer direction_weight is checked, not copied.
def peer_rules(rule_set: int) -> list[tuple[list[tuple[int, float]] | None, int, int]]:
    """(disjuncts, left term, right term) per firmware rule; disjuncts None = always.

    A rule fires with max over its disjuncts (sensor, weight) of
    min(near(sensor), weight).
    """
    out = []
    for antecedent, action in fz.RULE_SETS[rule_set]:
        lt, rt = fz.ACTIONS[action]
        if antecedent == fz.ALWAYS:
            disj = None
        elif antecedent < fz.N_SENSORS:
            disj = [(antecedent, 1.0)]
        else:
            d = antecedent - fz.N_SENSORS
            weights = [circular_weight(d, bearing) for bearing in SENSOR_BEARINGS]
            disj = [(i, w) for i, w in enumerate(weights) if w > 0]
        out.append((disj, lt, rt))
    return out


def _weight_terms(rule_set: int) -> dict[float, str]:
    ws = sorted({w for disj, _, _ in peer_rules(rule_set) if disj for _, w in disj if w < 1.0})
    return {w: f"w{round(w * 1000):04d}" for w in ws}


def random_readings(rng: Any, n: int) -> list[list[int]]:
    """n vectors of 8 reflected readings: per sensor 35 % zero, 10 % below the
    ramp, 35 % on the ramp, 20 % saturated (up to the ADC maximum)."""
    kind = rng.random((n, fz.N_SENSORS))
    below = rng.integers(1, fz.NEAR_LO + 1, (n, fz.N_SENSORS))
    ramp = rng.integers(fz.NEAR_LO, fz.NEAR_HI + 1, (n, fz.N_SENSORS))
    sat = rng.integers(fz.NEAR_HI, MAX_READING + 1, (n, fz.N_SENSORS))
    out = []
    for k in range(n):
        row = []
        for i in range(fz.N_SENSORS):
            u = kind[k, i]
            row.append(0 if u < 0.35 else int(below[k, i]) if u < 0.45 else
                       int(ramp[k, i]) if u < 0.80 else int(sat[k, i]))
        out.append(row)
    return out


# --------------------------------------------------------------------------- #
# Engines
# --------------------------------------------------------------------------- #
def build_firmware(rule_set: int, max_speed: int = 200) -> Infer:
    ctl = fz.FuzzyController(rule_set, max_speed)

    def infer(readings: list[int]) -> tuple[float, float]:
        ctl.infer(readings)
        return ctl.left, ctl.right

    return infer


def build_simpful(rule_set: int, max_speed: int = 200) -> tuple[Any, Infer]:
    """The rule base as a simpful zero-order Sugeno system; returns (system, infer).

    simpful's Sugeno output is sum(w*z)/sum(w) over the rules naming that
    output, each rule separately: the firmware's arithmetic.  Each firmware
    rule becomes two simpful rules (one consequent each), one per wheel.
    simpful's WEIGHT is not used: it scales the numerator only.
    """
    import simpful as sf  # type: ignore[import-untyped]

    system = sf.FuzzySystem(show_banner=False, verbose=False)
    near = [[fz.NEAR_LO, 0.0], [fz.NEAR_HI, 1.0]]  # extended flat on both sides
    for i in range(fz.N_SENSORS):
        system.add_linguistic_variable(
            f"S{i + 1}", sf.LinguisticVariable([sf.FuzzySet(points=near, term="near")],
                                               universe_of_discourse=[0, MAX_READING]))
    wterms = _weight_terms(rule_set)
    bias_sets = [sf.FuzzySet(points=[[0.0, 1.0], [1.0, 1.0]], term="always")]
    bias_sets += [sf.FuzzySet(points=[[0.0, w], [1.0, w]], term=name) for w, name in wterms.items()]
    system.add_linguistic_variable("BIAS", sf.LinguisticVariable(bias_sets, universe_of_discourse=[0, 1]))
    with contextlib.redirect_stdout(io.StringIO()):  # it prints " * Detected Sugeno model type"
        for t, z in enumerate(singletons(max_speed)):
            system.set_crisp_output_value(TERM_NAMES[t], z)

    rules = []
    for disj, lt, rt in peer_rules(rule_set):
        if disj is None:
            cond = "(BIAS IS always)"
        else:
            atoms = [f"(S{i + 1} IS near)" if w == 1.0 else f"((S{i + 1} IS near) AND (BIAS IS {wterms[w]}))"
                     for i, w in disj]
            cond = atoms[0]
            for a in atoms[1:-1]:
                cond = f"({cond} OR {a})"
            if len(atoms) > 1:
                cond = f"{cond} OR {atoms[-1]}"
        rules.append(f"IF {cond} THEN (LEFT IS {TERM_NAMES[lt]})")
        rules.append(f"IF {cond} THEN (RIGHT IS {TERM_NAMES[rt]})")
    system.add_rules(rules)
    names = [f"S{i + 1}" for i in range(fz.N_SENSORS)]
    system.set_variable("BIAS", 1.0, verbose=False)
    outputs = ["LEFT", "RIGHT"]

    def infer(readings: list[int]) -> tuple[float, float]:
        for name, r in zip(names, readings):
            system.set_variable(name, r, verbose=False)
        res = system.Sugeno_inference(outputs)
        return float(res["LEFT"]), float(res["RIGHT"])

    return system, infer


def build_fuzzylite(rule_set: int, max_speed: int = 200) -> Infer:
    """The rule base as a pyfuzzylite TakagiSugeno engine (weighted average)."""
    import fuzzylite as fl
    import numpy as np

    z = singletons(max_speed)
    wterms = _weight_terms(rule_set)
    inputs = [fl.InputVariable(f"s{i + 1}", minimum=0, maximum=MAX_READING,
                               terms=[fl.Ramp("near", fz.NEAR_LO, fz.NEAR_HI)]) for i in range(fz.N_SENSORS)]
    inputs.append(fl.InputVariable("bias", minimum=0, maximum=1,
                                   terms=[fl.Constant("always", 1.0)]
                                   + [fl.Constant(name, w) for w, name in wterms.items()]))
    outputs = [fl.OutputVariable(name, minimum=-max_speed, maximum=max_speed, default_value=0.0,
                                 aggregation=fl.UnboundedSum(), defuzzifier=fl.WeightedAverage(),
                                 terms=[fl.Constant(TERM_NAMES[t], z[t]) for t in range(len(z))])
               for name in ("left", "right")]
    rules = []
    for disj, lt, rt in peer_rules(rule_set):
        if disj is None:
            cond = "bias is always"
        else:
            cond = " or ".join(f"s{i + 1} is near" if w == 1.0 else f"(s{i + 1} is near and bias is {wterms[w]})"
                               for i, w in disj)
        rules.append(fl.Rule.create(f"if {cond} then left is {TERM_NAMES[lt]} and right is {TERM_NAMES[rt]}"))
    engine = fl.Engine(
        name=f"twinbot_{RULE_SET_NAMES[rule_set]}", input_variables=inputs, output_variables=outputs,
        rule_blocks=[fl.RuleBlock(conjunction=fl.Minimum(), disjunction=fl.Maximum(),
                                  implication=fl.Minimum(), activation=fl.General(), rules=rules)],
    )
    ivs = engine.input_variables[: fz.N_SENSORS]
    engine.input_variables[fz.N_SENSORS].value = 1.0
    left, right = engine.output_variables

    def infer(readings: list[int]) -> tuple[float, float]:
        for v, r in zip(ivs, readings):
            v.value = r
        engine.process()
        # pyfuzzylite 8 returns 1-element arrays (float() of those fails on numpy 2).
        return np.asarray(left.value).item(), np.asarray(right.value).item()

    return infer


def build_skfuzzy(rule_set: int, max_speed: int = 200) -> Infer:
    """A Mamdani/centroid build in scikit-fuzzy (it has no Sugeno engine): not
    the same arithmetic as the firmware, for timing only."""
    import numpy as np
    import skfuzzy as fuzz  # type: ignore[import-untyped]
    from skfuzzy import control as ctrl  # type: ignore[import-untyped]

    z = singletons(max_speed)
    wterms = _weight_terms(rule_set)
    sens = []
    for i in range(fz.N_SENSORS):
        a = ctrl.Antecedent(np.arange(0, MAX_READING + 1, 1), f"s{i + 1}")
        a["near"] = np.clip((a.universe - fz.NEAR_LO) / (fz.NEAR_HI - fz.NEAR_LO), 0.0, 1.0)
        sens.append(a)
    bias = ctrl.Antecedent(np.array([0.0, 1.0]), "bias")
    bias["always"] = np.array([1.0, 1.0])
    for w, name in wterms.items():
        bias[name] = np.array([w, w])
    half = 5
    outs = []
    for name in ("left", "right"):
        c = ctrl.Consequent(np.arange(-max_speed - 2 * half, max_speed + 2 * half + 1, 1), name,
                            defuzzify_method="centroid")
        for t, v in enumerate(z):
            c[TERM_NAMES[t]] = fuzz.trimf(c.universe, [v - half, v, v + half])
        outs.append(c)
    left, right = outs
    rules = []
    for disj, lt, rt in peer_rules(rule_set):
        if disj is None:
            ant = bias["always"]
        else:
            parts = [sens[i]["near"] if w == 1.0 else (sens[i]["near"] & bias[wterms[w]]) for i, w in disj]
            ant = parts[0]
            for p in parts[1:]:
                ant = ant | p
        rules.append(ctrl.Rule(ant, (left[TERM_NAMES[lt]], right[TERM_NAMES[rt]])))
    sim = ctrl.ControlSystemSimulation(ctrl.ControlSystem(rules), cache=False)
    names = [f"s{i + 1}" for i in range(fz.N_SENSORS)]

    def infer(readings: list[int]) -> tuple[float, float]:
        for name, r in zip(names, readings):
            sim.input[name] = r
        sim.input["bias"] = 1.0
        sim.compute()
        return float(sim.output["left"]), float(sim.output["right"])

    return infer


# (engine, distribution package, builder, what it is)
PEERS = (
    ("simpful", "simpful", lambda rs, ms: build_simpful(rs, ms)[1], "zero-order Sugeno (same arithmetic)"),
    ("pyfuzzylite", "pyfuzzylite", build_fuzzylite, "TakagiSugeno, WeightedAverage (same arithmetic)"),
    ("scikit-fuzzy", "scikit-fuzzy", build_skfuzzy, "Mamdani, centroid (different arithmetic)"),
)


# --------------------------------------------------------------------------- #
# Benchmark
# --------------------------------------------------------------------------- #
def _time(infer: Infer, vectors: list[list[int]], reference: list[tuple[float, float]] | None
          ) -> tuple[float, float | None]:
    for v in vectors[:20]:  # warm up
        infer(v)
    times = []
    worst = 0.0
    clock = time.perf_counter
    for k, v in enumerate(vectors):
        t0 = clock()
        out = infer(v)
        t1 = clock()
        times.append(t1 - t0)
        if reference is not None:
            ref = reference[k]
            worst = max(worst, abs(out[0] - ref[0]), abs(out[1] - ref[1]))
    return statistics.median(times) * 1e6, (worst if reference is not None else None)


def bench_inference(repeats: int = 1000, max_speed: int = 200, seed: int = 1,
                    peer_repeats: int | None = None) -> dict[str, Any]:
    """Median microseconds per inference, per engine and rule set.

    The peers, each reporting its largest difference from the firmware's
    setpoints over the timed inputs (a fast but wrong build would show);
    one not installed is listed under "unavailable" with the reason:
      simpful       zero-order Sugeno, crisp outputs: the same arithmetic
                    (rule-by-rule weighted average), agreeing to ~1 mm/s;
      pyfuzzylite   TakagiSugeno, Constant terms, WeightedAverage,
                    UnboundedSum, General activation: the same arithmetic;
      scikit-fuzzy  no Sugeno engine: a Mamdani build (triangles of
                    half-width 5 mm/s round the singletons, min activation,
                    max accumulation, centroid), so its setpoints differ.

    The firmware engine is timed on `repeats` random reading vectors, the
    peers on the first `peer_repeats` of them (default min(repeats, 300):
    they take 0.2 to 20 ms per inference, scikit-fuzzy the most, and 300
    calls give a stable median; all 2000 would take ~90 s).

    Returns {"engines": {name: {"version", "kind", "us": {rule set: us},
    "max_diff_mm_s": {rule set: largest |setpoint - firmware's| over the inputs}}},
    "unavailable": {package: reason}, "fastest_peer": {rule set: name},
    "speedup": {rule set: fastest peer's time / firmware's time},
    "speedup_vs_fastest_peer": the smaller of the two (None without peers),
    "table": format_table() of all that, ...}.
    """
    import numpy as np

    if repeats < 1:
        raise ValueError("repeats must be >= 1")
    peer_repeats = min(repeats, 300) if peer_repeats is None else max(1, min(peer_repeats, repeats))
    vectors = random_readings(np.random.default_rng(seed), repeats)
    result: dict[str, Any] = {
        "repeats": repeats, "peer_repeats": peer_repeats, "max_speed": max_speed, "seed": seed,
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "engines": {}, "unavailable": {}, "fastest_peer": {}, "speedup": {},
    }
    ours, reference = _time_firmware(vectors, max_speed)
    result["engines"]["twinbot"] = ours
    _time_peers(result, vectors[:peer_repeats],
                {rs: ref[:peer_repeats] for rs, ref in reference.items()}, max_speed)
    _rank_peers(result)
    result["table"] = format_table(result)
    return result


def _time_firmware(vectors: list[list[int]], max_speed: int
                   ) -> tuple[dict[str, Any], dict[str, list[tuple[float, float]]]]:
    """The firmware engine's entry, and its setpoints per rule set (the peers' reference)."""
    reference: dict[str, list[tuple[float, float]]] = {}
    ours: dict[str, Any] = {"version": "firmware/fuzzy.py", "kind": "integer zero-order Sugeno",
                            "us": {}, "max_diff_mm_s": {}}
    for rs, rs_name in enumerate(RULE_SET_NAMES):
        infer = build_firmware(rs, max_speed)
        reference[rs_name] = [infer(v) for v in vectors]
        ours["us"][rs_name], _ = _time(infer, vectors, None)
        ours["max_diff_mm_s"][rs_name] = 0.0
    return ours, reference


def _time_peers(result: dict[str, Any], vectors: list[list[int]],
                reference: dict[str, list[tuple[float, float]]], max_speed: int) -> None:
    """Time each peer into result["engines"], or say in result["unavailable"] why not."""
    import importlib.metadata as md

    for name, dist, build, kind in PEERS:
        try:
            version = md.version(dist)
            entry: dict[str, Any] = {"version": version, "kind": kind, "us": {}, "max_diff_mm_s": {}}
            with warnings.catch_warnings():  # scikit-fuzzy 0.5 warns on every call under numpy 2
                warnings.simplefilter("ignore", DeprecationWarning)
                for rs, rs_name in enumerate(RULE_SET_NAMES):
                    infer = build(rs, max_speed)
                    us, diff = _time(infer, vectors, reference[rs_name])
                    entry["us"][rs_name] = us
                    entry["max_diff_mm_s"][rs_name] = diff
        except Exception as exc:  # not installed, or broken against this numpy
            result["unavailable"][dist] = f"{type(exc).__name__}: {exc}"
            continue
        result["engines"][name] = entry


def _rank_peers(result: dict[str, Any]) -> None:
    """The fastest peer per rule set and the firmware's speedup over it."""
    ours = result["engines"]["twinbot"]
    for rs_name in RULE_SET_NAMES:
        peers = {n: e["us"][rs_name] for n, e in result["engines"].items() if n != "twinbot"}
        if peers:
            best = min(peers, key=peers.__getitem__)
            result["fastest_peer"][rs_name] = best
            result["speedup"][rs_name] = peers[best] / ours["us"][rs_name]
    result["speedup_vs_fastest_peer"] = min(result["speedup"].values()) if result["speedup"] else None


def format_table(res: dict[str, Any]) -> str:
    lines = [
        f"fuzzy inference, {res['python']} on {res['machine']}: median of {res['repeats']} calls "
        f"({res['peer_repeats']} for the peers) on random readings (seed {res['seed']}), "
        f"max_speed {res['max_speed']} mm/s",
        "",
        f"{'engine':<14}{'version':<19}{'first µs':>10}{'refined µs':>12}   {'max |Δ| mm/s':<17} kind",
        f"{'':<14}{'':<19}{'':>10}{'':>12}   {'first / refined':<17}",
    ]
    for name, e in res["engines"].items():
        d = e["max_diff_mm_s"]
        diff = f"{d['first']:.3f} / {d['refined']:.3f}"
        lines.append(f"{name:<14}{e['version']:<19}{e['us']['first']:>10.1f}{e['us']['refined']:>12.1f}"
                     f"   {diff:<17} {e['kind']}")
    lines.append("")
    for rs_name in RULE_SET_NAMES:
        if rs_name in res["speedup"]:
            lines.append(f"{rs_name}: firmware engine {res['speedup'][rs_name]:.1f}x faster than the "
                         f"fastest peer ({res['fastest_peer'][rs_name]})")
    for dist, why in res["unavailable"].items():
        lines.append(f"unavailable: {dist}: {why}")
    return "\n".join(lines)


if __name__ == "__main__":
    # python -m tools.bench.fuzzy [REPEATS [PEER_REPEATS]]
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 2000
    peers = int(sys.argv[2]) if len(sys.argv) > 2 else None
    print(bench_inference(n, peer_repeats=peers)["table"])
