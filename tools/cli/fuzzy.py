"""`twinbot fuzzy`: the human side of the fuzzy exploration controller.

Prints the rule base of firmware/fuzzy.py as a readable table or as
IEC 61131-7 FCL text, evaluates it for given readings, and draws the fuzzy
sets (docs/fuzzy.md).  The names, the circular sets' geometry and the
exporters are the library's (host_sim/controller/fuzzy_rulebase.py); this module is the
command and its figure.
"""
from __future__ import annotations

import argparse
from typing import Any

from firmware import fuzzy as fz
from host_sim.controller.fuzzy_rulebase import (
    ACTION_NAMES,
    ANTECEDENT_NAMES,
    DIRECTION_BEARINGS,
    RULE_SET_NAMES,
    TERM_NAMES,
    circular_weight,
    describe_rule,
    evaluate,
    fraction_text,
    rule_set_index,
    rule_table,
    singletons,
    to_fcl,
)


# --------------------------------------------------------------------------- #
# Figure
# --------------------------------------------------------------------------- #
COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")  # front, left, back, right


def plot_sets(path: str, max_speed: int = 200) -> None:
    """Draw the input and output sets and the actions (paper Figs. 16-18) to path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 9.5))
    (a, b), (c, d) = axes
    _draw_membership(a)
    _draw_circular_sets(b)
    _draw_singletons(c, max_speed)
    _draw_actions(d, max_speed)
    fig.suptitle("twinbot fuzzy exploration controller: sets and actions (paper Figs. 16-18)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _draw_membership(a: Any) -> None:
    """(a) the obstacle membership ramp, and its clipped half used by the circular sets."""
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


def _draw_circular_sets(b: Any) -> None:
    """(b) the four circular sets over the bearing, with the firmware's weights at the sensors."""
    bearings = [x / 2 for x in range(0, 721)]
    for dirn, name in enumerate(("front", "left", "back", "right")):
        ys = [circular_weight(dirn, t) for t in bearings]
        b.plot(bearings, ys, color=COLOURS[dirn], lw=2)
        for peak in ((0, 360) if dirn == 0 else (DIRECTION_BEARINGS[dirn],)):
            right_side = peak < 360
            b.text(peak + (6 if right_side else -6), 0.93, name, color=COLOURS[dirn], fontsize=10,
                   ha="left" if right_side else "right", va="center", fontweight="bold")
    for i in range(fz.N_SENSORS + 1):
        b.axvline(45 * i, color="0.75", lw=0.8, ls=":")
        b.text(45 * i, 1.04, f"S{i % fz.N_SENSORS + 1}", ha="center", va="bottom", fontsize=9)
    for i in range(fz.N_SENSORS):
        for dirn in range(4):
            w = fz.direction_weight(dirn, i)
            if w:
                b.plot([45 * i], [w / fz.ONE], "o", color=COLOURS[dirn], ms=5)
    b.set_xlim(-12, 372)
    b.set_ylim(-0.03, 1.15)
    b.set_xticks(range(0, 361, 45))
    b.set_xlabel("sensor bearing (degrees, counter-clockwise from front)")
    b.set_ylabel("weight of the bearing in the direction")
    b.set_title("(b) circular fuzzification (first rule set)")


def _draw_singletons(c: Any, max_speed: int) -> None:
    """(c) the output singletons per wheel; those only the refined set uses dashed."""
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


# Label placement of each action in panel (d): x, y in units of max_speed, ha, va.
ACTION_LABEL_PLACES = {
    "go ahead": (0.6, 0.42, "left", "center"),
    "go back": (-0.72, -0.95, "left", "center"),
    "go more on right": (1.06, 0.15, "left", "center"),
    "go more on left": (0.15, 1.07, "center", "bottom"),
    "go fast ahead": (1.06, 1.0, "left", "center"),
    "quick turn right": (1.06, -1.0, "left", "center"),
    "quick turn left": (-1.06, 1.0, "right", "center"),
}


def _draw_actions(d: Any, max_speed: int) -> None:
    """(d) each action as an arrow in the (left, right) wheel-speed plane."""
    z = singletons(max_speed)
    m = max_speed
    d.plot([-1.3 * m, 1.3 * m], [-1.3 * m, 1.3 * m], color="0.7", lw=0.8, ls=":")
    d.axhline(0, color="0.7", lw=0.8)
    d.axvline(0, color="0.7", lw=0.8)
    d.text(-0.45 * m, 0.3 * m, "turns left\n(right > left)", fontsize=9, color="0.45", ha="right")
    d.text(0.45 * m, -0.35 * m, "turns right\n(left > right)", fontsize=9, color="0.45", ha="left")
    refined_actions = {act for _, act in fz.RULES_REFINED} - {act for _, act in fz.RULES_FIRST}
    for act, (lt, rt) in enumerate(fz.ACTIONS):
        x, y = z[lt], z[rt]
        col = "tab:red" if act in refined_actions else "tab:blue"
        d.annotate("", xy=(x, y), xytext=(0, 0),
                   arrowprops={"arrowstyle": "->", "color": col, "lw": 1.8})
        d.plot([x], [y], "o", color=col)
        px, py, ha, va = ACTION_LABEL_PLACES.get(ACTION_NAMES[act], (x / m + 0.05, y / m, "left", "center"))
        d.text(px * m, py * m, f"{ACTION_NAMES[act]}\n({x:+d}, {y:+d})", fontsize=9, color=col, ha=ha, va=va)
    d.set_xlim(-1.75 * m, 1.75 * m)
    d.set_ylim(-1.2 * m, 1.3 * m)
    d.set_aspect("equal")
    d.set_xlabel("left wheel (mm/s)")
    d.set_ylabel("right wheel (mm/s)")
    d.set_title("(d) actions (red: added by the refined set)")


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
    from firmware import config
    from protocol import messages as M
    from tools.arguments import image_file, int_range

    _pid, _name, speed_lo, speed_hi, _default, _unit = M.param_by_name("max_speed")
    adc_max = (1 << config.ADC_BITS) - 1
    p = subparsers.add_parser(
        name, help=summary,
        description="The fuzzy exploration controller of firmware/fuzzy.py (paper section 5): "
                    "print its rule base as a table or as IEC 61131-7 FCL, draw its sets, "
                    "or evaluate it for eight reflected IR readings.",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--rules", choices=RULE_SET_NAMES, default="refined",
                   help="rule set (default: refined)")
    p.add_argument("--max-speed", type=int_range(max(1, speed_lo), speed_hi, unit="mm/s"), default=200, metavar="N",
                   help=f"wheel speed scale in mm/s, {max(1, speed_lo)}..{speed_hi} as the firmware's "
                        "max_speed: the terms are %% of it (default 200)")
    p.add_argument("--fcl", action="store_true", help="print the rule base as FCL text")
    p.add_argument("--plot", metavar="FILE", type=image_file,
                   help="write the figure of the sets (.png, .svg, .pdf ...)")
    p.add_argument("--eval", nargs=fz.N_SENSORS, type=int_range(0, adc_max, unit="ADC counts"), metavar="S",
                   help=f"evaluate for eight reflected readings S1 ... S8 (ADC counts, 0..{adc_max})")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tools.arguments import CliError

    rs = rule_set_index(args.rules)
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
             "near:  " + "  ".join(f"S{i + 1}={fraction_text(m) if m in (0, fz.ONE) else f'{m / fz.ONE:.3f}'}"
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
