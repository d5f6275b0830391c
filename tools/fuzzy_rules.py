"""`twinbot fuzzy`: the human side of the fuzzy exploration controller.

firmware/fuzzy.py holds the rule base as bare numbers (RAM is scarce on the
robot).  This module names those numbers, in the same order as the firmware
tables, prints the rule base as a readable table or as IEC 61131-7 FCL text,
evaluates it for given readings, and draws the fuzzy sets (docs/fuzzy.md).

The firmware is the source of truth: everything here is derived from its
tables, so a change there shows up here (and tests/test_fuzzy_peer.py checks
the names still match the paper's rule list).
"""
from __future__ import annotations

import argparse
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
    """The circular set of a direction at any bearing (0..1): the firmware's
    direction_weight extended to bearings between the sensors."""
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


def _antecedent_label(antecedent: int) -> str:
    if antecedent == fz.ALWAYS:
        return "always"
    if antecedent < fz.N_SENSORS:
        return f"{ANTECEDENT_NAMES[antecedent]} ({SENSOR_PLACES[antecedent]})"
    parts = []
    for i, w in antecedent_terms(antecedent):
        parts.append(f"S{i + 1}" if w == fz.ONE else f"min(S{i + 1}, {_frac(w)})")
    return f"{ANTECEDENT_NAMES[antecedent]} = max(" + ", ".join(parts) + ")"


def _frac(w: int) -> str:
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
            f"| {k} | {_antecedent_label(r['antecedent'])} | {r['then']} | "
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
    lo, hi = fz.NEAR_LO, fz.NEAR_HI
    used = [(a, act) for a, act in fz.RULE_SETS[rule_set]]
    # Terms each sensor needs: near, plus near clipped at each circular weight below 1.
    terms: dict[int, set[int]] = {i: {fz.ONE} for i in range(fz.N_SENSORS)}
    for a, _ in used:
        for i, w in antecedent_terms(a):
            terms[i].add(w)
    out_terms = sorted({t for _, act in used for t in fz.ACTIONS[act]})

    L: list[str] = []
    L += [
        f"(* twinbot fuzzy exploration controller, rule set \"{name}\" (paper section 5).",
        "   Generated by tools/fuzzy_rules.py from the tables of firmware/fuzzy.py;",
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
        "VAR_INPUT",
    ]
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
    if rule_set == 0:
        L += [
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
    L += [
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
    L += ["END_RULEBLOCK", "", "END_FUNCTION_BLOCK", ""]
    return "\n".join(L)


# --------------------------------------------------------------------------- #
# Figure
# --------------------------------------------------------------------------- #
def plot_sets(path: str, max_speed: int = 200) -> None:
    """Draw the input and output sets and the actions (paper Figs. 16-18) to path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = ("tab:blue", "tab:orange", "tab:green", "tab:red")
    fig, axes = plt.subplots(2, 2, figsize=(12, 9.5))
    (a, b), (c, d) = axes

    # (a) obstacle membership ramp.
    xs = list(range(0, 1001, 2))
    a.plot(xs, [fz.membership(x) / fz.ONE for x in xs], color="k", lw=2, label="near (firmware, /1024)")
    half = fz.NEAR_LO + (fz.NEAR_HI - fz.NEAR_LO) / 2
    a.plot([0, fz.NEAR_LO, half, 1000], [0, 0, 0.5, 0.5], color="tab:purple", ls="--",
           label="near_half = min(near, 1/2)\n(S2, S4, S6, S8 in the first set)")
    for x in (fz.NEAR_LO, fz.NEAR_HI):
        a.axvline(x, color="0.7", lw=0.8, ls=":")
    a.set_xticks([0, fz.NEAR_LO, 200, 400, fz.NEAR_HI, 1000])
    a.set_xlabel("reflected IR reading Si (ADC counts, ambient removed)")
    a.set_ylabel("membership")
    a.set_ylim(-0.03, 1.08)
    a.set_title("(a) input: obstacle on sensor Si")
    a.legend(loc="lower right", fontsize=9)

    # (b) circular sets.
    bearings = [x / 2 for x in range(0, 721)]
    for dirn, name in enumerate(("front", "left", "back", "right")):
        ys = [circular_weight(dirn, t) for t in bearings]
        b.plot(bearings, ys, color=colours[dirn], lw=2)
        for peak in ((0, 360) if dirn == 0 else (DIRECTION_BEARINGS[dirn],)):
            right_side = peak < 360
            b.text(peak + (6 if right_side else -6), 0.93, name, color=colours[dirn], fontsize=10,
                   ha="left" if right_side else "right", va="center", fontweight="bold")
    for i in range(fz.N_SENSORS + 1):
        b.axvline(45 * i, color="0.75", lw=0.8, ls=":")
        b.text(45 * i, 1.04, f"S{i % fz.N_SENSORS + 1}", ha="center", va="bottom", fontsize=9)
    for i in range(fz.N_SENSORS):
        for dirn in range(4):
            w = fz.direction_weight(dirn, i)
            if w:
                b.plot([45 * i], [w / fz.ONE], "o", color=colours[dirn], ms=5)
    b.set_xlim(-12, 372)
    b.set_ylim(-0.03, 1.15)
    b.set_xticks(range(0, 361, 45))
    b.set_xlabel("sensor bearing (degrees, counter-clockwise from front)")
    b.set_ylabel("weight of the bearing in the direction")
    b.set_title("(b) circular fuzzification (first rule set)")

    # (c) output singletons.
    z = singletons(max_speed)
    refined_only = {t for t in range(len(z))} - {t for _, act in fz.RULES_FIRST for t in fz.ACTIONS[act]}
    previous = None
    for t, v in enumerate(z):
        lift = 0.13 if previous is not None and v - previous < 0.25 * max_speed else 0.0
        previous = v if not lift else None
        style = "--" if t in refined_only else "-"
        col = "tab:red" if t in refined_only else "k"
        c.vlines(v, 0, 1, color=col, lw=2.5, ls=style)
        c.plot([v], [1], "o", color=col)
        c.vlines(v, 1, 1.02 + lift, color="0.6", lw=0.6)
        c.text(v, 1.04 + lift, f"{TERM_NAMES[t]}\n{v:+d}", ha="center", va="bottom", fontsize=9, color=col)
    c.axvline(0, color="0.7", lw=0.8, ls=":")
    c.set_xlim(-max_speed * 1.15, max_speed * 1.15)
    c.set_ylim(0, 1.45)
    c.set_yticks([0, 1])
    c.set_xlabel(f"wheel speed (mm/s, max_speed {max_speed}); same terms for the left and right wheel")
    c.set_ylabel("membership")
    c.set_title("(c) outputs: singletons per wheel (dashed: quick turns only)")

    # (d) actions in the wheel-speed plane.
    m = max_speed
    d.plot([-1.3 * m, 1.3 * m], [-1.3 * m, 1.3 * m], color="0.7", lw=0.8, ls=":")
    d.axhline(0, color="0.7", lw=0.8)
    d.axvline(0, color="0.7", lw=0.8)
    d.text(-0.45 * m, 0.3 * m, "turns left\n(right > left)", fontsize=9, color="0.45", ha="right")
    d.text(0.45 * m, -0.35 * m, "turns right\n(left > right)", fontsize=9, color="0.45", ha="left")
    refined_actions = {act for _, act in fz.RULES_REFINED} - {act for _, act in fz.RULES_FIRST}
    # Label placement (x, y in units of max_speed, ha, va) per action.
    place = {
        "go ahead": (0.6, 0.42, "left", "center"),
        "go back": (-0.72, -0.95, "left", "center"),
        "go more on right": (1.06, 0.15, "left", "center"),
        "go more on left": (0.15, 1.07, "center", "bottom"),
        "go fast ahead": (1.06, 1.0, "left", "center"),
        "quick turn right": (1.06, -1.0, "left", "center"),
        "quick turn left": (-1.06, 1.0, "right", "center"),
    }
    for act, (lt, rt) in enumerate(fz.ACTIONS):
        x, y = z[lt], z[rt]
        col = "tab:red" if act in refined_actions else "tab:blue"
        d.annotate("", xy=(x, y), xytext=(0, 0),
                   arrowprops={"arrowstyle": "->", "color": col, "lw": 1.8})
        d.plot([x], [y], "o", color=col)
        px, py, ha, va = place.get(ACTION_NAMES[act], (x / m + 0.05, y / m, "left", "center"))
        d.text(px * m, py * m, f"{ACTION_NAMES[act]}\n({x:+d}, {y:+d})", fontsize=9, color=col, ha=ha, va=va)
    d.set_xlim(-1.75 * m, 1.75 * m)
    d.set_ylim(-1.2 * m, 1.3 * m)
    d.set_aspect("equal")
    d.set_xlabel("left wheel (mm/s)")
    d.set_ylabel("right wheel (mm/s)")
    d.set_title("(d) actions (red: added by the refined set)")

    fig.suptitle("twinbot fuzzy exploration controller: sets and actions (paper Figs. 16-18)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- #
# CLI
# --------------------------------------------------------------------------- #
EXAMPLES = """\
examples:
  twinbot fuzzy                                  the refined rule set as a table
  twinbot fuzzy --rules first --fcl              the first rule set as IEC 61131-7 FCL
  twinbot fuzzy --plot fuzzy.png                 draw the sets (docs/fuzzy.png)
  twinbot fuzzy --eval 0 700 0 0 0 0 0 0         wheel setpoints for an obstacle on S2
"""


def register(subparsers: Any, name: str, summary: str) -> None:
    p = subparsers.add_parser(
        name, help=summary,
        description="The fuzzy exploration controller of firmware/fuzzy.py (paper section 5): "
                    "print its rule base as a table or as IEC 61131-7 FCL, draw its sets, "
                    "or evaluate it for eight reflected IR readings.",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--rules", choices=RULE_SET_NAMES, default="refined",
                   help="rule set (default: refined)")
    p.add_argument("--max-speed", type=int, default=200, metavar="N",
                   help="wheel speed scale in mm/s: the terms are %% of it (default 200)")
    p.add_argument("--fcl", action="store_true", help="print the rule base as FCL text")
    p.add_argument("--plot", metavar="FILE", help="write the figure of the sets (PNG, SVG, PDF)")
    p.add_argument("--eval", nargs=fz.N_SENSORS, type=int, metavar="S",
                   help="evaluate for eight reflected readings S1 ... S8 (ADC counts)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tools.cli import CliError

    rs = rule_set_index(args.rules)
    if args.max_speed <= 0:
        raise CliError(f"--max-speed {args.max_speed}: must be positive")
    if args.plot:
        try:
            plot_sets(args.plot, args.max_speed)
        except ImportError as exc:
            raise CliError(f"--plot needs matplotlib ({exc}); pip install matplotlib") from None
        except OSError as exc:
            raise CliError(f"--plot {args.plot}: {exc.strerror or exc}") from None
        print(f"wrote {args.plot}")
    if args.fcl:
        print(to_fcl(rs, args.max_speed), end="")
    if args.eval is not None:
        print(format_eval(rs, args.eval, args.max_speed))
    if not (args.plot or args.fcl or args.eval is not None):
        print(f"rule set \"{RULE_SET_NAMES[rs]}\", wheel speeds in mm/s for max_speed {args.max_speed}; "
              f"an obstacle is 'near' from {fz.NEAR_LO} (0) to {fz.NEAR_HI} (1) counts")
        print()
        print(rule_table(rs, args.max_speed))
    return 0


def format_eval(rule_set: int, readings: list[int], max_speed: int = 200) -> str:
    e = evaluate(rule_set, readings, max_speed)
    lines = [f"rule set \"{RULE_SET_NAMES[rule_set]}\", max_speed {max_speed} mm/s",
             "near:  " + "  ".join(f"S{i + 1}={_frac(m) if m in (0, fz.ONE) else f'{m / fz.ONE:.3f}'}"
                                   for i, m in enumerate(e["mu"]))]
    if e["direction_mu"] is not None:
        lines.append("dirs:  " + "  ".join(f"{n}={m / fz.ONE:.3f}"
                                           for n, m in zip(ANTECEDENT_NAMES[8:12], e["direction_mu"])))
    lines.append("fired:")
    z = singletons(max_speed)
    for (a, act), w in zip(fz.RULE_SETS[rule_set], e["strengths"]):
        if w:
            lt, rt = fz.ACTIONS[act]
            lines.append(f"  {w / fz.ONE:5.3f}  {describe_rule(a, act):<52} ({z[lt]:+d}, {z[rt]:+d})")
    lines.append(f"left = {e['left']} mm/s, right = {e['right']} mm/s")
    return "\n".join(lines)
