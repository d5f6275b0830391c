"""The verdict's judgements on the test block: whether a twin leaves only noise in a channel (near its
ceiling, white, no trend in time), how much of a located mismatch a fitted twin removes, and where a
parameter fitted on the two halves apart changes.  The rules and why: docs/diagnosis.md, "Verdict".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from host_sim.diagnosis.channels import ACCUMULATED, judged_windows
from host_sim.diagnosis.compare import Comparison
from host_sim.diagnosis.locate import EFFECT_MIN, noise_level, total_noise

# What is left may be the noise plus a mismatch of at most one noise level RMS (locate.EFFECT_MIN, the
# smallest bias the locator calls a mismatch): RMS <= sqrt(1 + 1) noise levels
# (tests/test_verdict.py::test_near_its_ceiling_is_noise_plus_at_most_one_noise_level).
NEAR_NOISE = math.sqrt(2.0)
# Whiteness: Ljung-Box over lags 2..WHITE_LAGS with Bartlett's variance (1 + 2 r1^2) / n.  A per-period
# increment of a rounded or tracked position is a lag-1 moving average (r1 = -1/2) when the twin is right,
# so lag 1 says nothing; any slow mismatch shows at every lag.  Asked only of a residual over one noise level
# RMS (EFFECT_MIN): below it the structure left is smaller than any mismatch the locator names, and a
# slowly varying reading's rounding is correlated under a right twin
# (tests/test_verdict.py::test_whiteness_passes_differenced_noise_and_fails_a_slow_residual).
WHITE_LAGS = 10
WHITE_ALPHA = 0.01  # over all the channels judged at once (Bonferroni): a 1 % false alarm per verdict
# No trend in time: each judged window's mean residual regressed on the window's time, t on (windows - 2)
# degrees of freedom (the window is the unit: periods within one are correlated), Bonferroni as above
# (tests/test_verdict.py::test_a_residual_that_drifts_over_the_test_block_has_a_trend).
TREND_ALPHA = 0.01
TOTALS = {total: channel for channel, total in ACCUMULATED.items()}  # travel -> forward, ...


@dataclass
class Judgement:
    """One channel on the test block: what a twin leaves there."""

    channel: str
    rms_noise: float  # the residual's RMS in noise levels
    white_p: float  # Ljung-Box p-value (nan for a window total: one value a window)
    trend_t: float  # t of the window means' regression on time
    near: bool
    white: bool
    steady: bool

    @property
    def explains(self) -> bool:
        return self.near and self.white and self.steady

    def to_json(self) -> dict[str, Any]:
        return {"channel": self.channel, "rms_in_noise": round(self.rms_noise, 3),
                "whiteness_p": None if math.isnan(self.white_p) else self.white_p, "trend_t": round(self.trend_t, 3),
                "near": bool(self.near), "white": bool(self.white), "steady": bool(self.steady)}


def channel_residual(cmp: Comparison, name: str, s: int = 0) -> tuple[np.ndarray, float, np.ndarray]:
    """(residual (W', T'), its noise level, the windows kept (W,) bool) of a channel or a window total on the
    windows it is judged on.  A total's noise is how far the totals stray from a proportion (locate.total_noise:
    its two ends' rounding, and what a window's start state cannot say, which a right twin leaves too)."""
    parent = TOTALS.get(name, name)
    ch = cmp.channel(parent)
    keep = judged_windows(parent, cmp.contact)
    resid = ch.residual(s)[keep]
    if name in TOTALS:
        return resid.sum(axis=1, keepdims=True), total_noise(ch, keep), keep
    return resid, max(noise_level(ch, resid), second_moment_noise(resid)), keep


def second_moment_noise(resid: np.ndarray) -> float:
    """The noise as a second moment, sqrt(mean of squared first differences / 2): the same moment as the RMS
    it is compared with, so a heavy-tailed white residual (a reading at a steep part of the IR law, moved
    by the tracker's noise) is 1 noise level RMS, where a robust spread (locate.noise_level) would put it at
    several; a slow mismatch still cancels in first differences
    (tests/test_verdict.py::test_a_heavy_tailed_white_residual_is_near_its_noise)."""
    d = np.diff(resid, axis=1)
    return float(np.sqrt(np.mean(d ** 2) / 2)) if d.size else 0.0


def whiteness_p(resid: np.ndarray, lags: int = WHITE_LAGS) -> float:
    """Ljung-Box p-value over lags 2..lags, each window demeaned and the lags taken within windows, the
    statistic divided by Bartlett's 1 + 2 r1^2 (a lag-1 moving average's variance of r_k, k > 1)."""
    r = resid - resid.mean(axis=1, keepdims=True)
    lags = min(lags, r.shape[1] - 2)
    denom = float((r * r).sum())
    if lags < 2 or denom == 0.0:
        return 1.0
    n, w = r.size, r.shape[0]
    rho = [float((r[:, k:] * r[:, :-k]).sum()) / denom for k in range(1, lags + 1)]
    q = n * (n + 2) * sum(rho[k - 1] ** 2 / (n - k * w) for k in range(2, lags + 1)) / (1 + 2 * rho[0] ** 2)
    return float(stats.chi2.sf(q, lags - 1))


def trend_t(resid: np.ndarray, times: np.ndarray) -> float:
    """t of the slope of the windows' mean residuals on their mean times (0 with fewer than 3 windows)."""
    y, x = resid.mean(axis=1), times.mean(axis=1)
    if len(y) < 3 or np.ptp(x) == 0.0:
        return 0.0
    slope, icpt = np.polyfit(x - x.mean(), y, 1)
    e = y - (icpt + slope * (x - x.mean()))
    se = math.sqrt(float(e @ e) / (len(y) - 2) / float((x - x.mean()) @ (x - x.mean())))
    return float(slope / se) if se > 0 else (0.0 if slope == 0 else math.copysign(math.inf, slope))


def judge_residual(name: str, resid: np.ndarray, noise: float, times: np.ndarray, tests: int = 1) -> Judgement:
    """One channel's residual (W, T') in its windows, with its noise level and times (W, T'): near its
    ceiling, white and without a trend, each test's alpha shared among `tests` channels (Bonferroni)."""
    rms = float(np.sqrt(np.mean(resid ** 2))) / noise
    white = whiteness_p(resid) if resid.shape[1] > 1 else math.nan
    tt = trend_t(resid, times)
    crit = float(stats.t.isf(TREND_ALPHA / tests / 2, max(resid.shape[0] - 2, 1)))
    return Judgement(name, rms, white, tt, bool(rms <= NEAR_NOISE),
                     bool(math.isnan(white) or rms <= EFFECT_MIN or white >= WHITE_ALPHA / tests), bool(abs(tt) < crit))


def judge_channels(cmp: Comparison, t: np.ndarray, names: list[str], s: int = 0) -> dict[str, Judgement]:
    """judge_residual of each channel (or window total) of `names` on every window of cmp (the test block,
    all judged); t: the recording's times (cmp's windows index it)."""
    out: dict[str, Judgement] = {}
    for name in names:
        resid, noise, keep = channel_residual(cmp, name, s)
        if resid.shape[0] == 0:
            continue
        times = t[cmp.windows.index[keep, :-1]]
        times = times if resid.shape[1] > 1 else times.mean(axis=1, keepdims=True)
        out[name] = judge_residual(name, resid, noise, times, max(len(names), 1))
    return out


def drifts(cmp: Comparison, t: np.ndarray, names: list[str]) -> list[tuple[Judgement, float]]:
    """The channels (or window totals) of `names` whose held-out windows' mean residual changes with time, each
    with that change from the first window to the last in noise levels: a trend beyond TREND_ALPHA (Bonferroni
    over `names`) that moves the mean by EFFECT_MIN noise levels or more, the smallest bias the locator names
    (tests/test_verdict.py::test_a_residual_that_drifts_over_the_held_out_windows_drifts)."""
    out = []
    for name in names:
        resid, noise, keep = channel_residual(cmp, name)
        held = cmp.windows.held_out[keep]
        resid = resid[held]
        if resid.shape[0] < 3 or not noise > 0:
            continue
        times = t[cmp.windows.index[keep, :-1]][held]
        times = times if resid.shape[1] > 1 else times.mean(axis=1, keepdims=True)
        j = judge_residual(name, resid, noise, times, max(len(names), 1))
        x = times.mean(axis=1)
        change = float(np.polyfit(x - x.mean(), resid.mean(axis=1), 1)[0] * np.ptp(x)) / noise
        if not j.steady and abs(change) >= EFFECT_MIN:
            out.append((j, change))
    return out


def removed_percent(before: Comparison, after: Comparison, names: list[str]) -> float:
    """How much of the located channels' residual a twin removes, in % of its sum of squares (each channel
    in the nominal twin's noise levels), on the same windows."""
    ss0 = ss1 = 0.0
    for name in names:
        r0, noise, _keep = channel_residual(before, name)
        r1, _noise, _keep = channel_residual(after, name)
        ss0 += float((r0 ** 2).sum()) / noise ** 2
        ss1 += float((r1 ** 2).sum()) / noise ** 2
    return 100.0 * (1.0 - ss1 / ss0) if ss0 > 0 else 0.0


def changed(first: list[float], second: list[float], first_ci: list[tuple[float, float]],
            second_ci: list[tuple[float, float]]) -> bool:
    """A parameter fitted on the two halves apart differs beyond their 95 % intervals: |a - b| over the
    root sum of squares of their half-widths (a 95 % test of the difference of two independent estimates)
    (tests/test_verdict.py::test_a_parameter_changes_when_the_halves_differ_beyond_their_intervals)."""
    for a, b, (a0, a1), (b0, b1) in zip(first, second, first_ci, second_ci):
        if abs(a - b) > math.hypot((a1 - a0) / 2, (b1 - b0) / 2):
            return True
    return False


def step_window(cmp: Comparison, names: list[str]) -> int:
    """The window at which a step change fits the located channels' window means best (least squares of a
    mean before and a mean after, channels in their noise levels, summed): where a parameter changes."""
    keep = np.ones(len(cmp.windows), dtype=bool)
    rows = []
    for name in names:
        resid, noise, kept = channel_residual(cmp, name)
        means = np.full(len(keep), np.nan)
        means[kept] = resid.mean(axis=1) / noise
        rows.append(means)
        keep &= kept
    if not rows or keep.sum() < 3:
        return 0
    y = np.array(rows)[:, keep]
    cost = [sum(float(np.var(r[:k]) * k + np.var(r[k:]) * (len(r) - k)) for r in y) for k in range(1, y.shape[1])]
    return int(np.flatnonzero(keep)[1 + int(np.argmin(cost))])
