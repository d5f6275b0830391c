"""The fuzzy exploration controller's rule base, named and exported (docs/fuzzy.md).

firmware/fuzzy.py holds the rule base as bare numbers and is the source of truth; this
module names them in the firmware's order, gives the circular sets' geometry in floating
point (circular_weight), explains one inference (evaluate), and exports the rule base as
a Markdown table (rule_table) or as IEC 61131-7 FCL (to_fcl) for `twinbot fuzzy`.
tests/test_fuzzy_peer.py checks the names against the paper's rule list.
"""
from __future__ import annotations

from fractions import Fraction
from typing import Any

from firmware import fuzzy as fz

# Names, index for index with the firmware tables.
TERM_NAMES = ("full_back", "back", "slow", "ahead", "fast")  # fz.TERMS
ACTION_NAMES = (  # fz.ACTIONS
    "go ahead",
    "go back",
    "go more on right",
    "go more on left",
    "go fast ahead",
    "quick turn right",
    "quick turn left",
)
ANTECEDENT_NAMES = (  # 0..7 sensors, 8..11 circular directions, 12 = fz.ALWAYS
    "S1", "S2", "S3", "S4", "S5", "S6", "S7", "S8",
    "front", "left", "back", "right",
    "always",
)
RULE_SET_NAMES = fz.RULE_SET_NAMES
# Where each sensor looks (paper section 3.3): S1 front, then counter-clockwise.
SENSOR_PLACES = ("front", "front-left", "left", "back-left", "back", "back-right", "right", "front-right")
SENSOR_BEARINGS = tuple(45 * i for i in range(fz.N_SENSORS))  # degrees counter-clockwise from the front
DIRECTION_BEARINGS = (0, 90, 180, 270)  # front, left, back, right, degrees counter-clockwise

assert len(TERM_NAMES) == len(fz.TERMS)
assert len(ACTION_NAMES) == len(fz.ACTIONS)
assert len(ANTECEDENT_NAMES) == fz.ALWAYS + 1
assert len(RULE_SET_NAMES) == len(fz.RULE_SETS)


# --------------------------------------------------------------------------- #
# Derived quantities
# --------------------------------------------------------------------------- #
def rule_set_index(name_or_index: str | int) -> int:
    if isinstance(name_or_index, int):
        if name_or_index not in (0, 1):
            raise ValueError(f"rule set {name_or_index}: expected 0 or 1")
        return name_or_index
    try:
        return RULE_SET_NAMES.index(name_or_index)
    except ValueError:
        raise ValueError(f"rule set {name_or_index!r}: expected one of {RULE_SET_NAMES}") from None


def singletons(max_speed: int = 200) -> tuple[int, ...]:
    """Wheel-speed singleton of each term in mm/s, exactly as the firmware scales it."""
    return tuple(pct * max_speed // 100 for pct in fz.TERMS)


def antecedent_terms(antecedent: int) -> list[tuple[int, int]]:
    """(sensor, weight 0..1024) pairs of one antecedent; [] for the unconditional rule.

    The antecedent's firing strength is max over the pairs of
    min(membership(sensor), weight): a sensor antecedent is one pair with
    weight 1024; a circular direction lists every sensor whose bearing lies
    in its set (fz.direction_weight), e.g. front = S1 (1), S2 (1/2), S8 (1/2).
    """
    if antecedent == fz.ALWAYS:
        return []
    if antecedent < fz.N_SENSORS:
        return [(antecedent, fz.ONE)]
    d = antecedent - fz.N_SENSORS
    pairs = [(i, fz.direction_weight(d, i)) for i in range(fz.N_SENSORS)]
    pairs = [(i, w) for i, w in pairs if w > 0]
    pairs.sort(key=lambda p: (-p[1], p[0]))
    return pairs


def circular_weight(direction: int, bearing_deg: float) -> float:
    """The circular set of a direction at any bearing (0..1), in floating point.

    Each direction is a triangle of half-width 90 degrees round its bearing.
    At the sensors' bearings (SENSOR_BEARINGS) it is the firmware's integer
    fz.direction_weight divided by fz.ONE; in between it draws the set."""
    diff = (bearing_deg - DIRECTION_BEARINGS[direction]) % 360.0
    diff = min(diff, 360.0 - diff)
    return max(0.0, 1.0 - diff / 90.0)


def rules(rule_set: int) -> list[dict[str, Any]]:
    """The rules of a set, named: antecedent, action, left and right terms."""
    out = []
    for antecedent, action in fz.RULE_SETS[rule_set]:
        lt, rt = fz.ACTIONS[action]
        out.append({
            "antecedent": antecedent, "action": action, "left_term": lt, "right_term": rt,
            "if": ANTECEDENT_NAMES[antecedent], "then": ACTION_NAMES[action],
        })
    return out


def describe_rule(antecedent: int, action: int) -> str:
    """One rule in the paper's words, e.g. "If an obstacle is on S2 then quick turn right"."""
    then = ACTION_NAMES[action]
    if antecedent == fz.ALWAYS:
        return then[0].upper() + then[1:]
    where = ANTECEDENT_NAMES[antecedent]
    if antecedent >= fz.N_SENSORS:
        where = "the " + where
    return f"If an obstacle is on {where} then {then}"


def antecedent_label(antecedent: int) -> str:
    """An antecedent for the table: "S2 (front-left)", or a direction as its max-of-min."""
    if antecedent == fz.ALWAYS:
        return "always"
    if antecedent < fz.N_SENSORS:
        return f"{ANTECEDENT_NAMES[antecedent]} ({SENSOR_PLACES[antecedent]})"
    parts = []
    for i, w in antecedent_terms(antecedent):
        parts.append(f"S{i + 1}" if w == fz.ONE else f"min(S{i + 1}, {fraction_text(w)})")
    return f"{ANTECEDENT_NAMES[antecedent]} = max(" + ", ".join(parts) + ")"


def fraction_text(w: int) -> str:
    """A weight 0..fz.ONE as an exact fraction, e.g. "1/2"."""
    return str(Fraction(w, fz.ONE))


def rule_table(rule_set: int, max_speed: int = 200) -> str:
    """The rule set as a Markdown table (readable on a terminal too)."""
    z = singletons(max_speed)
    lines = [
        "| # | if an obstacle is on | then | left wheel | right wheel |",
        "|---|---|---|---|---|",
    ]
    for k, r in enumerate(rules(rule_set), 1):
        lt, rt = r["left_term"], r["right_term"]
        lines.append(
            f"| {k} | {antecedent_label(r['antecedent'])} | {r['then']} | "
            f"{TERM_NAMES[lt]} {z[lt]:+d} | {TERM_NAMES[rt]} {z[rt]:+d} |"
        )
    return "\n".join(lines)


def evaluate(rule_set: int, readings: list[int], max_speed: int = 200) -> dict[str, Any]:
    """Run the firmware engine once and explain it: memberships, firing strengths, setpoints."""
    if len(readings) != fz.N_SENSORS:
        raise ValueError(f"expected {fz.N_SENSORS} readings, got {len(readings)}")
    ctl = fz.FuzzyController(rule_set, max_speed)
    ctl.infer(list(readings))
    mu = list(ctl.mu)
    dmu = list(ctl.direction_mu)
    strengths = []
    for antecedent, _action in fz.RULE_SETS[rule_set]:
        if antecedent == fz.ALWAYS:
            strengths.append(fz.ONE)
        elif antecedent < fz.N_SENSORS:
            strengths.append(mu[antecedent])
        else:
            strengths.append(dmu[antecedent - fz.N_SENSORS])
    return {"mu": mu, "direction_mu": dmu if rule_set == 0 else None, "strengths": strengths,
            "left": ctl.left, "right": ctl.right}


# --------------------------------------------------------------------------- #
# FCL (IEC 61131-7)
# --------------------------------------------------------------------------- #
def _num(x: Fraction | int | float) -> str:
    x = Fraction(x)
    if x.denominator == 1:
        return str(x.numerator)
    return f"{float(x):.6g}"


def _term_name(weight: int) -> str:
    if weight == fz.ONE:
        return "near"
    if weight * 2 == fz.ONE:
        return "near_half"
    return f"near_{weight}of{fz.ONE}"


def to_fcl(rule_set: int, max_speed: int = 200) -> str:
    """The rule base as IEC 61131-7 Fuzzy Control Language text."""
    rule_set = rule_set_index(rule_set)
    name = RULE_SET_NAMES[rule_set]
    z = singletons(max_speed)
    used = list(fz.RULE_SETS[rule_set])
    L = _fcl_preamble(name, max_speed)
    L += _fcl_variables()
    if rule_set == 0:
        L += _FCL_CIRCULAR_NOTE
    L += _fcl_fuzzify(_sensor_terms(used))
    L += _fcl_defuzzify(z, sorted({t for _, act in used for t in fz.ACTIONS[act]}))
    L += _fcl_ruleblock(name, used)
    L += ["END_FUNCTION_BLOCK", ""]
    return "\n".join(L)


def _sensor_terms(used: list[tuple[int, int]]) -> dict[int, set[int]]:
    """Terms each sensor needs: near, plus near clipped at each circular weight below 1."""
    terms: dict[int, set[int]] = {i: {fz.ONE} for i in range(fz.N_SENSORS)}
    for a, _ in used:
        for i, w in antecedent_terms(a):
            terms[i].add(w)
    return terms


def _fcl_preamble(name: str, max_speed: int) -> list[str]:
    """The opening comment (how the firmware's arithmetic maps onto FCL) and the block's name."""
    return [
        f"(* twinbot fuzzy exploration controller, rule set \"{name}\" (paper section 5).",
        "   Generated by tools/cli/fuzzy.py from the tables of firmware/fuzzy.py;",
        f"   wheel speeds in mm/s for max_speed = {max_speed} mm/s.",
        "",
        "   The firmware is a zero-order Sugeno engine: each rule's firing strength w",
        "   (AND = MIN, OR = MAX) weights a singleton per wheel, and each wheel's setpoint",
        "   is sum(w * z) / sum(w) over ALL rules, each rule counted separately.  In FCL",
        "   terms: singleton output terms, METHOD : COGS (centre of gravity for",
        "   singletons) with ACCU : NSUM.  NSUM adds the degrees of rules that share an",
        "   output term and divides every term by one common factor, which cancels in",
        "   COGS, so the result is the plain per-rule weighted average.  ACCU : MAX would",
        "   NOT be faithful: it keeps only the strongest of several rules giving the same",
        "   term (both 'go more on right' and 'go fast ahead' give the left wheel 'fast').",
        "   ACT is irrelevant for singletons (a singleton activated to w has height w).",
        "   The firmware computes in integers (memberships 0..1024, setpoints rounded",
        "   half up to whole mm/s), so it agrees with this text to about 1 mm/s. *)",
        "",
        f"FUNCTION_BLOCK twinbot_{name}",
        "",
    ]


def _fcl_variables() -> list[str]:
    """VAR_INPUT (the eight readings and the constant bias) and VAR_OUTPUT (the wheels)."""
    L = ["VAR_INPUT"]
    for i in range(fz.N_SENSORS):
        L.append(f"    s{i + 1} : REAL; (* S{i + 1}, {SENSOR_PLACES[i]}: reflected IR reading, "
                 f"ADC counts, ambient removed *)")
    L += [
        "    bias : REAL; (* always 1: carries the unconditional rule, FCL has no rule without IF *)",
        "END_VAR",
        "",
        "VAR_OUTPUT",
        "    left : REAL; (* left wheel setpoint, mm/s *)",
        "    right : REAL; (* right wheel setpoint, mm/s *)",
        "END_VAR",
        "",
    ]
    return L


# Why the first rule set's directions are written as ORs of clipped terms.
_FCL_CIRCULAR_NOTE = [
    "(* Circular fuzzification (paper Fig. 16).  The first rule set speaks of an",
    "   obstacle on the front, left, back or right.  Each direction is a triangle",
    "   90 degrees wide on either side of its bearing (front 0, left 90, back 180,",
    "   right 270, counter-clockwise) and sensor Si sits at 45*(i-1) degrees, so",
    "   S2 belongs to front and to left with weight 1/2 each.  The firmware computes",
    "       front = max over i of min(near(si), weight(front, Si))",
    "             = max(near(s1), min(near(s2), 1/2), min(near(s8), 1/2))",
    "   and likewise for left, back and right.  min(near(x), 1/2) is the term",
    "   near_half below (the near ramp clipped at 1/2), and the max is OR : MAX, so",
    "   each direction is ONE rule whose condition ORs its sensors: exactly the",
    "   firmware's max-of-min.  Rule weights (WITH 0.5) would not be faithful:",
    "   WITH multiplies (0.5 * near instead of min(near, 0.5)), and one weighted",
    "   rule per sensor would add the sensors' contributions instead of taking",
    "   their maximum. *)",
    "",
]


def _fcl_fuzzify(terms: dict[int, set[int]]) -> list[str]:
    """One FUZZIFY block per sensor (its near ramp, clipped as the rules need) and the bias."""
    lo, hi = fz.NEAR_LO, fz.NEAR_HI
    L: list[str] = []
    for i in range(fz.N_SENSORS):
        L.append(f"FUZZIFY s{i + 1}")
        for w in sorted(terms[i], reverse=True):
            top = Fraction(w, fz.ONE)
            x = lo + top * (hi - lo)
            note = "" if w == fz.ONE else f" (* min(near, {top}) *)"
            L.append(f"    TERM {_term_name(w)} := ({lo}, 0) ({_num(x)}, {_num(top)});{note}")
        L += ["END_FUZZIFY", ""]
    L += [
        "FUZZIFY bias",
        "    TERM always := (0, 1) (1, 1); (* 1 for any value *)",
        "END_FUZZIFY",
        "",
    ]
    return L


def _fcl_defuzzify(z: tuple[int, ...], out_terms: list[int]) -> list[str]:
    """One DEFUZZIFY block per wheel: the singletons the rules use, centre of gravity."""
    L: list[str] = []
    for wheel in ("left", "right"):
        L.append(f"DEFUZZIFY {wheel}")
        for t in out_terms:
            L.append(f"    TERM {TERM_NAMES[t]} := {z[t]}; (* {fz.TERMS[t]} % of max_speed *)")
        L += [
            "    METHOD : COGS;",
            "    DEFAULT := 0; (* never used: the unconditional rule always fires *)",
            f"    RANGE := ({min(z[t] for t in out_terms)} .. {max(z[t] for t in out_terms)});",
            "END_DEFUZZIFY",
            "",
        ]
    return L


def _fcl_ruleblock(name: str, used: list[tuple[int, int]]) -> list[str]:
    """The RULEBLOCK: operators, then one rule per firmware rule, in its order."""
    L = [
        f"RULEBLOCK {name}",
        "    AND : MIN;",
        "    OR : MAX;",
        "    ACT : MIN;",
        "    ACCU : NSUM;",
    ]
    for k, (a, act) in enumerate(used, 1):
        lt, rt = fz.ACTIONS[act]
        if a == fz.ALWAYS:
            cond = "bias IS always"
        else:
            cond = " OR ".join(f"s{i + 1} IS {_term_name(w)}" for i, w in antecedent_terms(a))
        L.append(f"    RULE {k} : IF {cond} THEN left IS {TERM_NAMES[lt]}, right IS {TERM_NAMES[rt]};"
                 f" (* {describe_rule(a, act)} *)")
    L += ["END_RULEBLOCK", ""]
    return L
