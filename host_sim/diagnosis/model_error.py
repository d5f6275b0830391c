"""A named effect's 95 % interval with the twin's own model error in it.

The fit's interval (fit.sandwich_intervals) is the spread across windows of the value the twin takes; a robot's
physics the twin lacks shifts that value alike in every window, so no spread shows it.  The reported interval
widens each half-width h to sqrt(h^2 + (MODEL_ERROR * size)^2), size the effect's distance from "not there" (or
a limit's own value).  MODEL_ERROR is a split-conformal quantile set on the proving ground's tuning split alone
(docs/diagnosis.md, "The twin's model error";
tests/test_verdict.py::test_the_reported_interval_adds_the_twins_model_error).
"""
from __future__ import annotations

import math

from host_sim.physics import effects as E
from host_sim.physics.params import RobotParams

# Of an effect's size: the split-conformal 95 % quantile (the 28th smallest of 28) of needed_share over the 28
# named effects of the tuning split's kept suites, 0.262, rounded up (its command: docs/diagnosis.md, "The twin's
# model error").  The reported intervals' coverage is then measured on the final split alone.
MODEL_ERROR = 0.27


def effect_size(name: str, value: float, datasheet: RobotParams) -> float:
    """min(|value - absent|, |value|): how far the effect is from not being there (its absent value on the
    datasheet's robot), or, for a limit far below its absent value, the limit itself."""
    absent = E.absent_values(datasheet, name)[0]
    return min(abs(value - absent), abs(value))


def with_model_error(name: str, value: float, ci: tuple[float, float], datasheet: RobotParams,
                     share: float = MODEL_ERROR) -> tuple[float, float]:
    """ci, each side widened in quadrature by share * the effect's size, within the library's bounds."""
    pad = share * effect_size(name, value, datasheet)
    lo, hi = E.bounds(name, datasheet)
    return (max(float(lo[0]), value - math.hypot(value - ci[0], pad)),
            min(float(hi[0]), value + math.hypot(ci[1] - value, pad)))


def needed_share(name: str, value: float, ci: tuple[float, float], true: float, datasheet: RobotParams) -> float:
    """The least share with_model_error needs for its interval to hold `true` (0 where ci already does):
    the score whose conformal quantile MODEL_ERROR is."""
    half = (ci[1] - value) if true > value else (value - ci[0])
    size = effect_size(name, value, datasheet)
    gap = math.sqrt(max(0.0, (true - value) ** 2 - half ** 2))
    return gap / size if size > 0 else (0.0 if gap == 0 else math.inf)
