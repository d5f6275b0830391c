"""The fuzzy controller (firmware/fuzzy.py) against a peer library, the paper, and its docs (docs/fuzzy.md).

The peer is simpful (zero-order Sugeno): the same rule base built there by
tools/bench/fuzzy.py build_simpful, with the circular weights taken from the floating-point
geometry (host_sim/controller/fuzzy_rulebase.py circular_weight), which is checked here against
the firmware's integer direction_weight.  simpful's Sugeno output is sum(w*z)/sum(w) over the
rules, as the firmware computes it, so the two may differ only by the firmware's fixed point:
within a_priori_bound, asserted with the 1 mm/s resolution on the seeded sample.
"""
from __future__ import annotations

import argparse
import itertools
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware import fuzzy as fz
from host_sim.controller import fuzzy_rulebase as rb
from host_sim.controller.fuzzy_rulebase import SENSOR_BEARINGS, circular_weight, singletons
from tools.cli import fuzzy as fr
from tools.bench.fuzzy import build_simpful, random_readings

ROOT = Path(__file__).resolve().parents[1]
N_VECTORS = 10_000
SEED = 20240611
MAX_SPEED = 200
FIRST, REFINED = 0, 1
BOTH = pytest.mark.parametrize("rule_set", [FIRST, REFINED], ids=["first", "refined"])


def infer(rule_set: int, readings: list[int], max_speed: int = MAX_SPEED) -> tuple[int, int]:
    ctl = fz.FuzzyController(rule_set, max_speed)
    ctl.infer(list(readings))
    return ctl.left, ctl.right


def mirror(readings: list[int]) -> list[int]:
    """Left-right mirror image: S2<->S8, S3<->S7, S4<->S6 (S1, S5 stay)."""
    return [readings[(fz.N_SENSORS - i) % fz.N_SENSORS] for i in range(fz.N_SENSORS)]


def a_priori_bound(rule_set: int, wheel: int, max_speed: int = MAX_SPEED) -> float:
    """How far (mm/s) the firmware's fixed point may take a setpoint from simpful's exact one.

    * each firing strength w_k is low by 0 <= d_k < 1/1024 (memberships are
      floored to 1/1024; min and max keep that error and its sign), so the
      unrounded setpoint moves by  z' - z = -sum_k d_k (z_k - z) / W'  with
      W' >= 1 (the unconditional rule always fires at exactly 1).  All d_k have
      one sign, so |z' - z| <= max(P, N) / 1024 with P = sum over z_k > z of
      (z_k - z) and N = sum over z_k < z of (z - z_k); P falls and N rises with
      z, so over the reachable range [z_lo, z_hi] the worst case is P(z_lo) or
      N(z_hi) (z_lo, z_hi are found on the vertices of the weight box: z is
      monotone in each weight);
    * the setpoint is then rounded half up to whole mm/s: at most 1/2 more.

    At max_speed 200 that bound is 0.99 mm/s for the first rule set (so within 1 mm/s is
    guaranteed) and 2.38 mm/s for the refined one (the bound ignores that many rules firing at
    once also raises W').
    """
    z = singletons(max_speed)
    z0 = None
    zs = []
    for antecedent, action in fz.RULE_SETS[rule_set]:
        v = z[fz.ACTIONS[action][wheel]]
        if antecedent == fz.ALWAYS:
            z0 = v
        else:
            zs.append(v)
    assert z0 is not None
    reach = [(z0 + sum(v for v, on in zip(zs, pick) if on)) / (1 + sum(pick))
             for pick in itertools.product((0, 1), repeat=len(zs))]
    lo, hi = min(reach), max(reach)
    p_lo = sum(v - lo for v in zs if v > lo)
    n_hi = sum(hi - v for v in zs if v < hi)
    return 0.5 + max(p_lo, n_hi) / fz.ONE


def exact_setpoints(rule_set: int, readings: list[int], max_speed: int = MAX_SPEED) -> tuple[int, int]:
    """The firmware's quantised memberships, averaged in exact rationals, rounded half up."""
    mu = [fz.membership(r) for r in readings]
    z = singletons(max_speed)
    num = [Fraction(0), Fraction(0)]
    den = Fraction(0)
    for antecedent, action in fz.RULE_SETS[rule_set]:
        if antecedent == fz.ALWAYS:
            w = fz.ONE
        elif antecedent < fz.N_SENSORS:
            w = mu[antecedent]
        else:
            d = antecedent - fz.N_SENSORS
            w = max(min(mu[i], fz.direction_weight(d, i)) for i in range(fz.N_SENSORS))
        for wheel in (0, 1):
            num[wheel] += w * z[fz.ACTIONS[action][wheel]]
        den += w
    return tuple(int((n / den + Fraction(1, 2)).__floor__()) for n in num)  # type: ignore[return-value]


# --------------------------------------------------------------------------- #
# Against simpful
# --------------------------------------------------------------------------- #
@pytest.fixture(scope="module")
def vectors() -> list[list[int]]:
    return random_readings(np.random.default_rng(SEED), N_VECTORS)


@BOTH
def test_matches_simpful_within_fixed_point_resolution(rule_set: int, vectors: list[list[int]]) -> None:
    pytest.importorskip("simpful")
    _, peer = build_simpful(rule_set, MAX_SPEED)
    ctl = fz.FuzzyController(rule_set, MAX_SPEED)
    diffs = np.empty((len(vectors), 2))
    mismatched_rounding = 0
    for k, v in enumerate(vectors):
        ctl.infer(v)
        sl, sr = peer(v)
        diffs[k] = (ctl.left - sl, ctl.right - sr)
        mismatched_rounding += (ctl.left, ctl.right) != (int(np.floor(sl + 0.5)), int(np.floor(sr + 0.5)))
    worst = np.abs(diffs).max(axis=0)
    print(f"\n{rb.RULE_SET_NAMES[rule_set]}: max |firmware - simpful| over {len(vectors)} vectors: "
          f"left {worst[0]:.4f}, right {worst[1]:.4f} mm/s; "
          f"a-priori bound {a_priori_bound(rule_set, 0):.3f} / {a_priori_bound(rule_set, 1):.3f}; "
          f"{mismatched_rounding} vectors where simpful rounded half up differs")
    for wheel in (0, 1):
        assert worst[wheel] <= a_priori_bound(rule_set, wheel) + 1e-6
    assert worst.max() <= 1.0
    # The fixed point should rarely change the rounded result at all.
    assert mismatched_rounding <= len(vectors) // 10


def test_a_priori_bounds() -> None:
    """Pin the derived bounds (a_priori_bound): the first set is guaranteed within 1 mm/s."""
    assert [round(a_priori_bound(FIRST, w), 3) for w in (0, 1)] == [0.993, 0.993]
    assert [round(a_priori_bound(REFINED, w), 3) for w in (0, 1)] == [2.382, 2.382]


@BOTH
def test_firmware_is_exact_rational_arithmetic_rounded_half_up(rule_set: int, vectors: list[list[int]]) -> None:
    for v in vectors[:2000]:
        assert infer(rule_set, v) == exact_setpoints(rule_set, v)


def test_circular_weights_match_the_geometry() -> None:
    """The firmware's integer weights are the library's float sets at the sensors' bearings
    (the float sets feed the simpful peer above, so this ties the peer to the firmware)."""
    for d in range(4):
        for i in range(fz.N_SENSORS):
            assert fz.direction_weight(d, i) == round(fz.ONE * circular_weight(d, SENSOR_BEARINGS[i]))
    # Every sensor belongs to the four directions with total weight 1.
    for i in range(fz.N_SENSORS):
        assert sum(fz.direction_weight(d, i) for d in range(4)) == fz.ONE


@pytest.mark.parametrize("direction, bearing, weight", [
    (0, 0.0, 1.0), (0, 45.0, 0.5), (0, 315.0, 0.5), (0, 22.5, 0.75), (0, -22.5, 0.75),
    (0, 90.0, 0.0), (0, 180.0, 0.0), (1, 90.0, 1.0), (1, 135.0, 0.5), (2, 180.0, 1.0),
    (3, 270.0, 1.0), (3, 0.0, 0.0), (3, 337.5, 0.25), (3, 630.0, 1.0),
])
def test_circular_sets_are_triangles_of_half_width_90_degrees(direction: int, bearing: float,
                                                              weight: float) -> None:
    """The float sets by hand (paper Fig. 16): bearings between the sensors and past 360 too."""
    assert circular_weight(direction, bearing) == pytest.approx(weight)


def test_simpful_takes_max_of_min_for_the_circular_sets() -> None:
    """S2 and S8 both saturated: front = max(min(1, 1/2), min(1, 1/2)) = 1/2, not 1."""
    pytest.importorskip("simpful")
    system, peer = build_simpful(FIRST, MAX_SPEED)
    readings = [0, 900, 0, 0, 0, 0, 0, 900]
    # front 1/2 (go back), left 1/2 (more right), right 1/2 (more left)
    expect = (110 + 0.5 * (-160 + 200 + 30)) / 2.5
    assert peer(readings) == pytest.approx((expect, expect))
    assert infer(FIRST, readings) == (round(expect), round(expect))


# --------------------------------------------------------------------------- #
# Behaviour (paper section 5), both rule sets
# --------------------------------------------------------------------------- #
SAT = 1000  # well past NEAR_HI


def only(sensor: int, value: int = SAT) -> list[int]:
    r = [0] * fz.N_SENSORS
    r[sensor] = value
    return r


@BOTH
def test_nothing_seen_goes_ahead(rule_set: int) -> None:
    left, right = infer(rule_set, [0] * 8)
    assert left == right == fz.TERMS[3] * MAX_SPEED // 100 > 0


@BOTH
def test_obstacle_on_s1_goes_back(rule_set: int) -> None:
    left, right = infer(rule_set, only(0))
    assert left == right < 0


@BOTH
def test_obstacle_on_s2_turns_right(rule_set: int) -> None:
    left, right = infer(rule_set, only(1))
    assert left > right
    if rule_set == REFINED:  # quick turn right: the right wheel runs backwards
        assert right < 0 < left


@BOTH
def test_obstacle_on_s8_turns_left(rule_set: int) -> None:
    left, right = infer(rule_set, only(7))
    assert right > left
    if rule_set == REFINED:
        assert left < 0 < right
    assert (left, right) == infer(rule_set, only(1))[::-1]


@BOTH
def test_obstacle_behind_speeds_up(rule_set: int) -> None:
    left, right = infer(rule_set, only(4))
    assert left == right > infer(rule_set, [0] * 8)[0]


@BOTH
@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(0, 4095), min_size=8, max_size=8))
def test_mirrored_inputs_give_mirrored_outputs(rule_set: int, readings: list[int]) -> None:
    left, right = infer(rule_set, readings)
    assert infer(rule_set, mirror(readings)) == (right, left)


def test_first_rule_set_does_not_turn_away_from_a_wall_the_refined_one_does() -> None:
    """The paper: with the first rule set 'this front obstacle can make the robot
    just to stop in front of it'; the quick turns of S2 and S8 fix that.

    Facing a wall, the first set never turns: the circular sets cap S2 and S8
    at 1/2 on the left and right, so once both exceed half membership (370
    counts) the 'more right' and 'more left' rules cancel even for an oblique
    wall.  The refined set turns away from the side that sees more."""
    for s1 in range(0, 1001, 10):
        for s2, s8 in ((0, 0), (150, 150), (520, 420), (900, 380)):
            wall = [s1, s2, 0, 0, 0, 0, 0, s8]
            left, right = infer(FIRST, wall)
            assert left == right, wall
            if s2 > s8:
                rl, rr = infer(REFINED, wall)
                assert rl > rr, wall


def test_first_rule_set_stops_only_if_the_diagonal_sensors_see_little() -> None:
    """Head-on, 'go ahead' (+110) averages with 'go back' (-160): with S1 alone
    the robot stops where near(S1) = 110/160 (494 counts).  But 'more right'
    and 'more left' both drive forwards (fast + slow), so when S2 and S8 see
    the wall too the first set stops only while their membership h stays
    under 50/230 (about 183 counts): the left wheel's numerator is
    110 - 160 max(near(S1), h) + 230 h.  Past that it keeps creeping forwards,
    +22 mm/s with every front sensor saturated.  The refined set stops at 494
    counts whatever S2 and S8 read (their quick turns cancel)."""
    stop = int(fz.NEAR_LO + Fraction(110, 160) * (fz.NEAR_HI - fz.NEAR_LO))
    assert stop == 493
    for rule_set in (FIRST, REFINED):
        assert infer(rule_set, only(0, stop)) == (0, 0)
        assert infer(rule_set, only(0, SAT))[0] < 0
    for diag in (0, 100, 150, 180):
        assert infer(FIRST, [SAT, diag, 0, 0, 0, 0, 0, diag])[0] < 0, diag
    for diag in (190, 370, SAT):
        assert infer(FIRST, [SAT, diag, 0, 0, 0, 0, 0, diag])[0] > 0, diag
    assert infer(FIRST, [SAT, SAT, 0, 0, 0, 0, 0, SAT]) == (22, 22)
    for diag in (0, 190, 370, SAT):
        assert infer(REFINED, [stop, diag, 0, 0, 0, 0, 0, diag]) == (0, 0)


# --------------------------------------------------------------------------- #
# Names, FCL, figure, CLI, docs
# --------------------------------------------------------------------------- #
PAPER_FIRST = [
    "Go ahead",
    "If an obstacle is on the front then go back",
    "If an obstacle is on the left then go more on right",
    "If an obstacle is on the right then go more on left",
    "If an obstacle is on the back then go fast ahead",
]
PAPER_REFINED = [
    "Go ahead",
    "If an obstacle is on S1 then go back",
    "If an obstacle is on S3 then go more on right",
    "If an obstacle is on S7 then go more on left",
    "If an obstacle is on S5 then go fast ahead",
    "If an obstacle is on S2 then quick turn right",
    "If an obstacle is on S4 then go fast ahead",  # "go fast ahead and go more on right"
    "If an obstacle is on S4 then go more on right",
    "If an obstacle is on S6 then go fast ahead",
    "If an obstacle is on S6 then go more on left",
    "If an obstacle is on S8 then quick turn left",
]


def test_names_follow_the_firmware_tables_and_the_paper() -> None:
    assert [rb.describe_rule(a, act) for a, act in fz.RULES_FIRST] == PAPER_FIRST
    assert [rb.describe_rule(a, act) for a, act in fz.RULES_REFINED] == PAPER_REFINED
    z = dict(zip(rb.TERM_NAMES, singletons(MAX_SPEED)))
    assert z["full_back"] < z["back"] < 0 < z["slow"] < z["ahead"] < z["fast"]
    for name, (lt, rt) in zip(rb.ACTION_NAMES, fz.ACTIONS):
        left, right = singletons(MAX_SPEED)[lt], singletons(MAX_SPEED)[rt]
        if "right" in name:
            assert left > right, name
        elif "left" in name:
            assert right > left, name
        else:
            assert left == right, name


def compile_fcl(text: str):  # type: ignore[no-untyped-def]
    """A tiny FCL interpreter for what to_fcl writes: piecewise-linear input
    terms (flat outside), singleton outputs, OR = MAX, AND = MIN, COGS with
    NSUM, i.e. sum(w*z)/sum(w) over the rules.  Returns readings -> (left, right)."""
    text = re.sub(r"\(\*.*?\*\)", "", text, flags=re.S)
    terms: dict[tuple[str, str], tuple[tuple[float, ...], tuple[float, ...]]] = {}
    for var, body in re.findall(r"FUZZIFY (\w+)(.*?)END_FUZZIFY", text, re.S):
        for term, pts in re.findall(r"TERM (\w+) := ((?:\([^)]*\)\s*)+);", body):
            xy = [tuple(map(float, p.split(","))) for p in re.findall(r"\(([^)]*)\)", pts)]
            terms[var, term] = tuple(zip(*xy))  # type: ignore[assignment]
    outs: dict[tuple[str, str], float] = {}
    for var, body in re.findall(r"DEFUZZIFY (\w+)(.*?)END_DEFUZZIFY", text, re.S):
        assert "METHOD : COGS;" in body
        for term, val in re.findall(r"TERM (\w+) := (-?[\d.]+);", body):
            outs[var, term] = float(val)
    assert "ACCU : NSUM;" in text and "OR : MAX;" in text and "AND : MIN;" in text

    def atom(text: str) -> tuple[str, str]:
        m = re.fullmatch(r"(\w+) IS (\w+)", text.strip())
        assert m, text
        return m.group(1), m.group(2)

    rules = [([[atom(a) for a in conj.split(" AND ")] for conj in cond.split(" OR ")],
              [atom(part) for part in concl.split(",")])
             for cond, concl in re.findall(r"RULE \d+ : IF (.*?) THEN (.*?);", text)]
    assert rules

    def run(readings: list[int]) -> tuple[float, float]:
        values = {f"s{i + 1}": float(r) for i, r in enumerate(readings)} | {"bias": 1.0}
        num = {"left": 0.0, "right": 0.0}
        den = {"left": 0.0, "right": 0.0}
        for cond, concl in rules:
            # np.interp is flat outside the first and last point, like FCL.
            w = max(min(float(np.interp(values[v], *terms[v, t])) for v, t in conj) for conj in cond)
            for var, term in concl:
                num[var] += w * outs[var, term]
                den[var] += w
        return num["left"] / den["left"], num["right"] / den["right"]

    return run


@BOTH
def test_fcl_contains_every_rule_and_computes_the_same(rule_set: int, vectors: list[list[int]]) -> None:
    text = rb.to_fcl(rule_set, MAX_SPEED)
    assert text.startswith("(*") and "FUNCTION_BLOCK twinbot_" in text and text.rstrip().endswith("END_FUNCTION_BLOCK")
    rules = re.findall(r"RULE (\d+) : IF (.*?) THEN left IS (\w+), right IS (\w+);", text)
    assert [int(k) for k, *_ in rules] == list(range(1, len(fz.RULE_SETS[rule_set]) + 1))
    for (_k, cond, lt, rt), (antecedent, action) in zip(rules, fz.RULE_SETS[rule_set]):
        assert (lt, rt) == tuple(rb.TERM_NAMES[t] for t in fz.ACTIONS[action])
        if antecedent < fz.N_SENSORS:
            assert cond == f"s{antecedent + 1} IS near"
        elif antecedent == fz.ALWAYS:
            assert cond == "bias IS always"
        else:  # a direction: its full-weight sensor and two half-weight ones
            assert cond.count(" OR ") == 2 and cond.count("near_half") == 2
    run = compile_fcl(text)
    bound_l, bound_r = a_priori_bound(rule_set, 0), a_priori_bound(rule_set, 1)
    for v in vectors[:2000]:
        left, right = infer(rule_set, v)
        fl_, fr_ = run(v)
        assert abs(left - fl_) <= bound_l and abs(right - fr_) <= bound_r


def test_fcl_scales_with_max_speed() -> None:
    text = rb.to_fcl(REFINED, 150)
    assert "TERM fast := 150;" in text and "TERM full_back := -150;" in text
    assert "TERM slow := 22;" in text  # 15 % of 150 = 22.5, truncated like the firmware


def test_plot_sets_writes_a_png(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    path = tmp_path / "sets.png"
    fr.plot_sets(str(path))
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    svg = tmp_path / "sets.svg"
    assert _cli(["--plot", str(svg)], capsys) == f"wrote {svg}\n"
    assert svg.read_text().lstrip().startswith("<?xml")


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    parser = argparse.ArgumentParser(prog="twinbot")
    fr.register(parser.add_subparsers(dest="command"), "fuzzy", "the fuzzy controller")
    args = parser.parse_args(["fuzzy", *argv])
    assert args.func(args) == 0
    return capsys.readouterr().out


def test_cli(capsys: pytest.CaptureFixture[str]) -> None:
    out = _cli([], capsys)
    assert "quick turn left" in out and "| 11 |" in out
    out = _cli(["--rules", "first"], capsys)
    assert "front = max(S1, min(S2, 1/2), min(S8, 1/2))" in out
    assert _cli(["--rules", "first", "--fcl"], capsys) == rb.to_fcl(FIRST)
    out = _cli(["--eval", "0", "1000", "0", "0", "0", "0", "0", "0"], capsys)
    assert out.rstrip().endswith(f"left = {infer(REFINED, only(1))[0]} mm/s, right = {infer(REFINED, only(1))[1]} mm/s")
    out = _cli(["--max-speed", "100", "--eval", *["0"] * 8], capsys)
    assert "left = 55 mm/s, right = 55 mm/s" in out


def test_docs_hold_the_current_tables_and_figure() -> None:
    doc = (ROOT / "docs" / "fuzzy.md").read_text(encoding="utf-8")
    for rs in (FIRST, REFINED):
        assert rb.rule_table(rs) in doc
    assert "fuzzy.png" in doc and (ROOT / "docs" / "fuzzy.png").exists()


def test_bench_inference_smoke() -> None:
    from tools.bench.fuzzy import bench_inference, format_table

    res = bench_inference(repeats=4)
    assert res["engines"]["twinbot"]["us"]["refined"] > 0
    for name in ("simpful", "pyfuzzylite"):  # same arithmetic as the firmware
        if name in res["engines"]:
            assert max(res["engines"][name]["max_diff_mm_s"].values()) <= 1.0
    assert set(res["speedup"]) == {"first", "refined"}
    assert res["speedup_vs_fastest_peer"] == min(res["speedup"].values())
    assert res["table"] == format_table(res) and "twinbot" in res["table"]
