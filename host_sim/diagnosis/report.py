"""The verdict and its evidence: a terminal summary and a stable JSON document (docs/diagnosis.md).

Verdicts: "match" (nothing located: the twin reproduces the recording to
its noise), "explained" (every located mismatch removed by named effects),
"partly explained", "unexplained" (located, and nothing names it — never a
wrong name).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from host_sim.diagnosis.compare import Comparison, compare_all
from host_sim.diagnosis.windows import DEFAULT_SECONDS
from host_sim.diagnosis.words import sentence
from host_sim.params import RobotParams
from host_sim.recording import Recording
from host_sim.world import World

MIN_WINDOWS = 6  # 1 s windows: fewer and the held-out judgement rests on one or two windows
MIN_MOVING = 0.2  # share of periods in which a wheel turns: less and the recording says little of the physics


class DiagnosisError(ValueError):
    """The recording cannot be diagnosed; the message says why and what would help."""


@dataclass
class Diagnosis:
    recording: str
    verdict: str
    comparisons: list[Comparison]
    located: list[dict[str, Any]] = field(default_factory=list)
    effects: list[dict[str, Any]] = field(default_factory=list)
    fit_before: dict[str, float] = field(default_factory=dict)
    fit_after: dict[str, float] = field(default_factory=dict)
    unexplained: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {"recording": self.recording, "verdict": self.verdict, "located": self.located,
                "effects": self.effects, "fit": {"before": _finite(self.fit_before), "after": _finite(self.fit_after)},
                "unexplained": self.unexplained, "notes": self.notes}

    def summary(self) -> str:
        lines = [f"{self.recording}: {self.verdict}"]
        lines += [f"  note: {n}" for n in self.notes]
        for item in self.located:
            lines.append(f"  - {item['words']} (fit {item['fit_before']:.0f} %)")
        lines.append("  held-out fit % per channel (1 s windows): " + ", ".join(
            f"{k} {v:.0f}" for k, v in self.fit_before.items() if not k.startswith("amb_")))
        return "\n".join(lines)


def _finite(d: dict[str, float]) -> dict[str, float | None]:
    return {k: (round(v, 2) if math.isfinite(v) else None) for k, v in d.items()}


def check_data(rec: Recording, world: World | None) -> list[str]:
    """Refuse what cannot be diagnosed; return notes on what this recording cannot show."""
    period = rec.sample_period
    if len(rec) * period < MIN_WINDOWS * DEFAULT_SECONDS[0]:
        raise DiagnosisError(f"the recording lasts {len(rec) * period:.1f} s: too short to diagnose "
                             f"(at least {MIN_WINDOWS * DEFAULT_SECONDS[0]:.0f} s; 60-90 s is better)")
    moving = np.abs(np.diff(rec.enc, axis=0)).max(axis=1) > 0
    if moving.mean() < MIN_MOVING:
        raise DiagnosisError(f"the wheels turn in only {100 * moving.mean():.0f} % of the periods: too little "
                             f"excitation to diagnose (run the identification manoeuvre: twinbot serial PORT --excite)")
    notes = []
    if rec.pose is None:
        notes.append("no tracker pose: judged on the encoders and the battery only; effects on the body's motion "
                     "(track width vs wheel radius, slip) and on the IR sensors cannot be told apart without it")
    elif world is None or world.n_walls == 0:
        notes.append("no walls known: the IR sensors are not judged")
    return notes


def diagnose(rec: Recording, params: RobotParams, world: World | None, *,
             seconds: tuple[float, ...] = DEFAULT_SECONDS, progress: Callable[[str], None] | None = None) -> Diagnosis:
    notes = check_data(rec, world)
    say = progress or (lambda _text: None)
    say("comparing")
    comparisons = compare_all(rec, params, world, seconds)
    first = comparisons[0]
    if first.contact.all():
        raise DiagnosisError("the robot touches a wall in every window: stuck against a wall the whole time, "
                             "nothing else can be judged")
    located = [{"channel": f.channel, "regime": f.regime, "spans": [list(s) for s in f.spans],
                "fit_before": first.fit.get(f.channel, float("nan")), "words": sentence(f),
                "mean_residual": f.mean, "z": f.z, "whiteness_p": first.whiteness.get(f.channel),
                "input_lag_periods": first.lag.get(f.channel, (None,))[0]}
               for f in first.findings]
    verdict = "match" if not located else "unexplained"
    result = Diagnosis(str(rec.path or "recording"), verdict, comparisons, located, fit_before=dict(first.fit),
                       notes=notes)
    if located:
        result.unexplained = [{"channel": item["channel"], "regime": item["regime"], "spans": item["spans"],
                               "words": item["words"]} for item in located]
    if int(first.contact.sum()):
        result.notes.append(f"{int(first.contact.sum())} of {len(first.contact)} windows touch a wall: judged apart "
                            f"(channel 'contact')")
    return result
