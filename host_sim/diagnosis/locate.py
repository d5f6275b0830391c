"""Locate: where and when a channel's residuals are not noise, by regime and by time.

Five rules, each deciding through a margin (its weakest test over its threshold; at 1 it locates): a
regime bin's bias, a window total's proportional error (locate_scale), a wheel's scatter without a bias,
the IR ring's readings running behind the pose, and a wheel that lags the twin.  The rules, their
thresholds and why: docs/diagnosis.md, "Locate".
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from host_sim.diagnosis.channels import ACCUMULATED, SENSOR_NAMES, WHEELS, Channel, sensor_channel
from host_sim.diagnosis.windows import Windows, near_a_wall
from host_sim.physics.params import RobotParams
from host_sim.recordings.recording import Recording
from host_sim.physics.world import World

Z_MIN = 5.0
EFFECT_MIN = 1.0  # noise levels: a smaller mean mismatch is within the noise of a single period
RELATIVE_MIN = 0.05  # of the recorded signal's mean size in the bin: smaller does not matter to the robot
SPAN_MIN_S = 0.4
SMOOTH_S = 0.5
TIMING = "timing_"  # regime of sensor k: "timing_k", closing on its wall (0), steady (1), drawing away (2)
TIMING_RATE = 0.05  # m/s along a sensor's axis: slower is steady
TIMING_SENSORS_MIN = 3  # sensors that must show a reading running behind before it is located
TIMING_Z = 3.0  # each half on each sensor: three sensors at 3 pool (Stouffer, sum z / sqrt 3) to 5.2 >= Z_MIN
REGIME_SHARE_MIN = 0.05  # a regime variable must explain this share of the residual's variation to be named
READING_LAG_Z = 4.0  # each sensor's lag (reading_lag_findings), on TIMING_SENSORS_MIN sensors at least
READING_LAG_SPREAD = 0.5  # of the median lag: the sensors that show a latency show the same one
READING_LAG_REGIME = "as it changes"  # "sensor S5 back's reading runs 25 ms behind the tracked pose's as it changes"
SCALE_MIN = 0.02  # a path or turn 2 % off the twin's: an odometry error worth naming
SCALE_MIN_COUNTS = 0.01  # a count, 1 %: the firmware's speed loop takes back most of an encoder's error
# A window total's noise in per-period noise levels: its two ends (first differences of differenced white
# noise put the per-period level at sqrt(3) of the noise, a total's two ends at sqrt(2)).
TOTAL_NOISE = float(np.sqrt(2.0 / 3.0))
SCALE_WINDOWS_MIN = 6  # windows away from the walls a proportional error is judged on
SCALE_SIGNAL_MIN = 10.0  # window totals (RMS) must be this many times their noise for a proportion to mean much
SCALE_REGIME = "window by window"  # "the robot turns 3 % less than the twin, window by window"
SCATTER_MIN = 5.0  # a wheel's residual RMS in noise levels beyond which it is a mismatch with or without a bias
# ... or in the encoder's rounding (its noise floor): a wheel that chatters period to period (a gear's play
# in the speed loop) raises its first differences, and so the noise they estimate, more than its RMS
SCATTER_FLOOR_MIN = 8.0
LAG_BLOCK = 5  # periods summed before a wheel's lag is judged: the encoder's rounding telescopes in a sum
LAG_MIN_S = 0.008  # s: a wheel that answers the twin's speed changes this much late (or early) is a mismatch
LAG_REGIME = "whenever its speed changes"
SCATTER_REGIME = 2.0  # a bin whose mean square is this many times the wheel's is where it scatters most


@dataclass
class Regimes:
    """Labels of every window period (W, T - 1): name -> (label array, {label: words})."""

    labels: dict[str, tuple[np.ndarray, dict[int, str]]] = field(default_factory=dict)

    def add(self, name: str, values: np.ndarray, words: dict[int, str]) -> None:
        self.labels[name] = (values, words)


# The least of a kind of motion, or of a sensor facing a wall, that judges what it shows: with less, those
# effects are said to be poorly judged (a "match" is then weak evidence).
MIN_REGIME_S = 4.0


def near_wall_seconds(rec: Recording, reg: Regimes) -> list[float]:
    """Per IR pair: the seconds its axis met a wall within 12 cm of the rim (its `wall_k` regimes 0 and 1; 0.0
    where the regimes have no walls)."""
    return [float((reg.labels[f"wall_{k}"][0] < 2).sum()) * rec.sample_period if f"wall_{k}" in reg.labels else 0.0
            for k in range(rec.n_ir)]


def _wheel_speeds(rec: Recording, idx: np.ndarray, p: RobotParams) -> np.ndarray:
    """(W, T - 1, 2) rim speeds (m/s) from the recorded encoders, per period."""
    d = np.diff(rec.enc[idx], axis=1).astype(float)
    dt = np.diff(rec.t[idx], axis=1)[..., None]
    return d * (2 * np.pi * p.wheel_radius / p.ticks_per_rev) / dt


def regimes(rec: Recording, windows: Windows, p: RobotParams, world: World | None) -> Regimes:
    idx = windows.index
    rows = idx[:, :-1]  # a period is labelled by its first row
    out = Regimes()
    v = _wheel_speeds(rec, idx, p)
    for w, side in enumerate(("left", "right")):
        speed = np.abs(v[..., w])
        out.add(f"speed_{side[0]}", np.digitize(speed, [0.005, 0.06]),
                {0: f"with the {side} wheel at rest", 1: f"at low {side}-wheel speed", 2: f"at high {side}-wheel speed"})
        cmd = rec.cmd[rows][..., w]
        out.add(f"command_{side[0]}", np.sign(cmd).astype(int) + 1,
                {0: f"with a negative {side} command", 1: f"with no {side} command", 2: f"with a positive {side} command"})
    mean = v.mean(axis=-1)
    accel = np.diff(np.concatenate([mean[:, :1], mean], axis=1), axis=1) / np.diff(rec.t[idx], axis=1)  # recorded
    # signed, not pooled: a slipping wheel runs ahead of the twin's when the speed rises and behind it when
    # the speed falls, and a heavy robot the other way round; pooled, the two halves cancel
    out.add("acceleration", (accel > 0.3).astype(int) + 2 * (accel < -0.3),
            {0: "when cruising", 1: "when the speed rises", 2: "when the speed falls"})
    yaw = (v[..., 1] - v[..., 0]) / (2 * p.half_axle)
    out.add("turning", np.digitize(yaw, [-0.5, 0.5]), {0: "when turning right", 1: "when going straight",
                                                        2: "when turning left"})
    out.add("direction", (mean < -0.005).astype(int) + 2 * (np.abs(mean) <= 0.005),
            {0: "when driving forwards", 1: "when driving backwards", 2: "when the robot stands or turns on the spot"})
    if np.ptp(rec.vbat) > 0.05:
        out.add("battery", (rec.vbat[rows] < np.median(rec.vbat)).astype(int),
                {0: "at high battery voltage", 1: "at low battery voltage"})
    if rec.pose is not None:
        heading = np.mod(rec.pose[rows][..., 2] + np.pi / 4, 2 * np.pi) // (np.pi / 2)
        out.add("heading", heading.astype(int), {0: "heading +x", 1: "heading +y", 2: "heading -x", 3: "heading -y"})
        if world is not None:
            _wall_regimes(out, rec, rows, world, p.ir_bearings)
    return out


def _wall_regimes(out: Regimes, rec: Recording, rows: np.ndarray, world: World, bearings: tuple[float, ...]) -> None:
    """Per sensor: how far the wall it looks at is (along its axis, from the body's rim), and whether it
    closes on that wall or draws away from it over the period (`timing_findings`)."""
    assert rec.pose is not None
    dist, _angle, hit = world.cast_robots(rec.pose[rows], bearings, 1.0)
    period = rec.t[rows + 1] - rec.t[rows]  # each period as long as it was recorded
    after, _angle, hit_after = world.cast_robots(rec.pose[rows + 1], bearings, 1.0)
    for k in range(len(bearings)):
        d = np.where(hit[..., k], dist[..., k], np.inf)
        out.add(f"wall_{k}", np.digitize(d, [0.09, 0.18]),
                {0: f"with a wall within 3 cm of {SENSOR_NAMES[k]}", 1: f"with a wall 3-12 cm from {SENSOR_NAMES[k]}",
                 2: f"with no wall near {SENSOR_NAMES[k]}"})
        seen = hit[..., k] & hit_after[..., k] & (d < 0.18)
        rate = np.subtract(after[..., k], dist[..., k], out=np.zeros(seen.shape), where=seen) / period
        out.add(f"{TIMING}{k}", np.digitize(rate, [-TIMING_RATE, TIMING_RATE]),
                {0: f"while {SENSOR_NAMES[k]} closes on a wall", 1: "",
                 2: f"while {SENSOR_NAMES[k]} draws away from a wall"})


def timing_findings(chans: list[Channel], resids: dict[str, np.ndarray], keep: np.ndarray, reg: Regimes,
                    t: np.ndarray) -> list[Finding]:
    """IR sensors whose readings run behind (or ahead of) the pose: below the twin's while closing on a
    wall and above it while drawing away (or the reverse), each half a mismatch at |z| >= TIMING_Z.  A
    latency is the whole ring's, so this is located only when TIMING_SENSORS_MIN sensors show it the
    same way round (one sensor alone is not a latency); their evidence pools, so each sensor is held to
    less than Z_MIN: one that sees a wall for a few dozen periods gives each half a small z.  One finding
    per sensor, in its larger bin.
    Tested: tests/test_diagnosis.py::test_readings_that_run_behind_the_pose_are_located_on_the_ring."""
    found: dict[bool, list[Finding]] = {True: [], False: []}  # behind the pose / ahead of it
    for ch, regime, words, r, lab, y, sigma in _timing_sensors(chans, resids, keep, reg):
        closing, receding = (_bin_stats(r[lab == v], sigma, y[lab == v], TIMING_Z) for v in (0, 2))
        if closing is None or receding is None or closing["mean"] * receding["mean"] >= 0:
            continue
        bins = [{"regime": words[0], "key": f"{regime}=0", **closing},
                {"regime": words[2], "key": f"{regime}=2", **receding}]
        larger = max(bins, key=lambda b: abs(float(b["mean"])))  # type: ignore[arg-type]
        found[closing["mean"] < 0].append(Finding(ch.name, str(larger["regime"]), str(larger["key"]),
                                                  spans(resids[ch.name], keep, t, sigma), float(larger["mean"]),
                                                  float(larger["z"]), sigma, bins))  # type: ignore[arg-type]
    return next((same for same in found.values() if len(same) >= TIMING_SENSORS_MIN), [])


def _reading_lags(chans: list[Channel], resids: dict[str, np.ndarray], keep: np.ndarray,
                  unjudged: np.ndarray | None) -> Iterator[tuple[Channel, float, float]]:
    """Per IR sensor (kept windows, judged readings): (channel, lag in periods, its z).  A reading that runs
    tau behind the pose is the twin's reading tau earlier, recorded - twin = -tau d(twin)/dt: the residual
    regressed on the twin's centred change (which leaves out the period's own tracker noise, so that noise
    cannot pass for a lag), with a standard error robust to a residual that grows with the change."""
    for ch in chans:
        if not ch.name.startswith("ir_"):
            continue
        twin, r = ch.y_hat[keep, 0], resids[ch.name][keep]
        x = (twin[:, 2:] - twin[:, :-2]) / 2.0
        r = r[:, 1:-1]
        if unjudged is not None:
            judged = ~unjudged[keep][:, 1:-1, int(ch.name[3:])]
            x, r = x[judged], r[judged]
        sxx = float((x * x).sum())
        if sxx <= 0.0:
            continue
        tau = -float((r * x).sum()) / sxx
        se = float(np.sqrt((((r + tau * x) * x) ** 2).sum())) / sxx
        yield ch, tau, tau / se if se > 0 else 0.0


def reading_lag_findings(chans: list[Channel], resids: dict[str, np.ndarray], keep: np.ndarray,
                         unjudged: np.ndarray | None, t: np.ndarray, period: float) -> list[Finding]:
    """IR sensors whose readings run a common time behind (or ahead of) the pose (_reading_lags): located
    when TIMING_SENSORS_MIN sensors show it the same way round at |z| >= READING_LAG_Z, their lags within
    READING_LAG_SPREAD of the median's (a latency is the ring's; an offset or a turned sensor skews one
    sensor's lag, or several by unlike amounts).  Where closing and drawing-away periods are few (a
    manoeuvre that meets walls in a few dozen periods), their means are noise (timing_findings) while the
    reading's proportion to its change is not
    (tests/test_diagnosis.py::test_readings_in_proportion_to_their_change_give_the_rings_latency)."""
    lags = [(ch, tau, z) for ch, tau, z in _reading_lags(chans, resids, keep, unjudged) if abs(z) >= READING_LAG_Z]
    for late in (True, False):
        same = [(ch, tau, z) for ch, tau, z in lags if (tau > 0) == late]
        if len(same) < TIMING_SENSORS_MIN:
            continue
        mid = float(np.median([tau for _c, tau, _z in same]))
        same = [(ch, tau, z) for ch, tau, z in same if abs(tau - mid) <= READING_LAG_SPREAD * abs(mid)]
        if len(same) >= TIMING_SENSORS_MIN:
            out = []
            for ch, tau, z in same:
                r = resids[ch.name]
                sigma = noise_level(ch, r[keep])
                out.append(Finding(ch.name, READING_LAG_REGIME, "lag", spans(r, keep, t, sigma), float(r[keep].mean()),
                                   float(z), sigma, [{"regime": READING_LAG_REGIME, "key": "lag", "mean": tau * period,
                                                      "z": float(z), "n": float(r[keep].size)}], lag=tau * period))
            return out
    return []


def reading_lag_margin(chans: list[Channel], resids: dict[str, np.ndarray], keep: np.ndarray,
                       unjudged: np.ndarray | None) -> tuple[float, str]:
    """How near reading_lag_findings comes to a latency: of the sensors the same way round, the
    TIMING_SENSORS_MIN-th largest |z| over READING_LAG_Z (the lags' spread aside)."""
    ways: dict[bool, list[tuple[float, str]]] = {True: [], False: []}
    for ch, tau, z in _reading_lags(chans, resids, keep, unjudged):
        ways[tau > 0].append((abs(z) / READING_LAG_Z, ch.name))
    return _ring_margin(ways)


def _ring_margin(ways: dict[bool, list[tuple[float, str]]]) -> tuple[float, str]:
    """Of the sensors' margins, late and early apart, the TIMING_SENSORS_MIN-th largest either way round and
    the sensors that reach it: a latency is the ring's, so it takes that many sensors."""
    best = (0.0, "")
    for found in ways.values():
        found.sort(reverse=True)
        if len(found) >= TIMING_SENSORS_MIN:
            best = max(best, (found[TIMING_SENSORS_MIN - 1][0], " ".join(n for _m, n in found[:TIMING_SENSORS_MIN])))
    return best


def _timing_sensors(chans: list[Channel], resids: dict[str, np.ndarray], keep: np.ndarray, reg: Regimes) -> Iterator[
        tuple[Channel, str, dict[int, str], np.ndarray, np.ndarray, np.ndarray, float]]:
    """The IR sensors the timing rule judges (those with a closing / drawing-away regime), each with its regime's
    name and words and, on the kept windows, its residual, labels, recorded readings and noise level."""
    for ch in chans:
        regime = f"{TIMING}{ch.name[3:]}"
        if not ch.name.startswith("ir_") or regime not in reg.labels:
            continue
        labels, words = reg.labels[regime]
        r = resids[ch.name][keep]
        yield ch, regime, words, r, labels[keep], ch.y[keep], noise_level(ch, r)


def contact_windows(rec: Recording, windows: Windows, p: RobotParams, world: World | None) -> np.ndarray:
    """(W,) bool: the recorded robot touches a wall somewhere in the window (tracker needed)."""
    return near_a_wall(rec, windows.index, p, world)


@dataclass
class Finding:
    """A channel whose residual is not noise, and where."""

    channel: str
    regime: str  # the regime bin where the mismatch is largest, in words ("" if everywhere alike)
    regime_key: str  # e.g. "speed_l=1"
    spans: list[tuple[float, float]]
    mean: float  # mean residual in that regime (recorded - twin)
    z: float
    noise: float
    bins: list[dict[str, object]]  # every significant bin: {regime, key, mean, z, n}
    rms: float | None = None  # a scatter without a bias (scatter_finding): the RMS residual in that regime
    lag: float | None = None  # a wheel that runs behind the twin (lag_finding): s, > 0 late


def noise_level(ch: Channel, resid: np.ndarray) -> float:
    """The residual's noise: the larger of the channel's floor and what its first differences say.

    A slow mismatch cancels in first differences; white noise of variance s^2 gives them 2 s^2.
    """
    d = np.diff(resid, axis=1).ravel()
    mad = float(np.median(np.abs(d - np.median(d)))) / 0.6745 / np.sqrt(2) if d.size else 0.0
    return max(ch.noise_floor, mad, 1e-12)


def relevant_regimes(channel: str) -> tuple[str, ...]:
    """The regime variables that can tell something about a channel (prefixes of Regimes names)."""
    if channel in ("wheel_l", "wheel_r"):
        side = channel[-1]
        return (f"speed_{side}", f"command_{side}", "acceleration", "turning", "direction", "battery")
    if channel in ("forward", "lateral", "heading_rate"):
        return ("speed_", "command_", "acceleration", "turning", "direction", "battery", "heading")
    if sensor_channel(channel):
        return (f"wall_{channel.split('_')[1]}", "heading", "turning", "direction")
    return ("battery", "speed_", "acceleration")


def locate_channel(ch: Channel, resid: np.ndarray, keep: np.ndarray, reg: Regimes, t: np.ndarray) -> Finding | None:
    """Where the residual (W, T - 1) of the kept windows is not noise, or None if it is noise everywhere.

    The regime named is the one that explains most of the residual's
    variation (the largest share of its sum of squares between the bins of
    one regime variable); within it, the bin with the largest mismatch.  A
    residual alike in every regime is located "everywhere" (regime "").
    """
    r = resid[keep]
    if r.size == 0:
        return None
    sigma = noise_level(ch, r)
    bins: list[dict[str, object]] = []
    y = _signal(ch, keep, r)
    overall = _bin_stats(r.ravel(), sigma, y.ravel())
    if overall is not None:
        bins.append({"regime": "", "key": "all", **overall})
    best_share, best_bin = 0.0, None
    total = float(((r - r.mean()) ** 2).sum()) or 1.0
    wanted = relevant_regimes(ch.name)
    for name, (labels, words) in reg.labels.items():
        if not name.startswith(wanted):
            continue
        lab = labels[keep]
        found = []
        between = 0.0
        for value, text in words.items():
            part = r[lab == value]
            if part.size:
                between += part.size * (float(part.mean()) - float(r.mean())) ** 2
            stat = _bin_stats(part, sigma, y[lab == value])
            if stat is not None:
                found.append({"regime": text, "key": f"{name}={value}", **stat})
        bins += found
        share = between / total
        if found and share > best_share:
            best_share, best_bin = share, max(found, key=lambda b: abs(float(b["mean"])))  # type: ignore[arg-type]
    if not bins:
        return None
    chosen = best_bin if best_bin is not None and best_share >= REGIME_SHARE_MIN else (
        bins[0] if bins[0]["key"] == "all" else best_bin)
    assert chosen is not None
    return Finding(ch.name, str(chosen["regime"]), str(chosen["key"]), spans(resid, keep, t, sigma),
                   float(chosen["mean"]), float(chosen["z"]), sigma, bins)  # type: ignore[arg-type]


def _signal(ch: Channel, keep: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The recorded signal a bias is held against (bin_margin: RELATIVE_MIN of it), or the channel's own
    scale (ambient: the lamps' light), scaled up where the channel's model is known only to a wider share
    (Channel.tolerance); zeros for a level."""
    if not ch.relative:
        return np.zeros_like(r)
    return (ch.y if ch.scale is None else ch.scale)[keep] * max(1.0, ch.tolerance / RELATIVE_MIN)


def bias_margin(ch: Channel, resid: np.ndarray, keep: np.ndarray, reg: Regimes) -> tuple[float, str]:
    """The largest bin margin of a channel (bin_margin), over the whole and every regime bin that
    locate_channel judges, and that bin's key: locate_channel locates the channel at 1 or more."""
    r = resid[keep]
    if r.size == 0:
        return 0.0, ""
    sigma = noise_level(ch, r)
    y = _signal(ch, keep, r)
    parts = [("all", np.ones(r.shape, dtype=bool))]
    for name, (labels, words) in reg.labels.items():
        if name.startswith(relevant_regimes(ch.name)):
            parts += [(f"{name}={value}", labels[keep] == value) for value in words]
    return max(((bin_margin(r[m], sigma, y[m])[0], key) for key, m in parts if int(m.sum()) >= 10),
               default=(0.0, ""))


def timing_margin(chans: list[Channel], resids: dict[str, np.ndarray], keep: np.ndarray,
                  reg: Regimes) -> tuple[float, str]:
    """How near timing_findings comes to a latency, and on which sensors: per sensor the weaker of its two
    halves' margins at TIMING_Z (0 unless they lie opposite ways round), and of the sensors the same way
    round the TIMING_SENSORS_MIN-th largest: at 1 or more a latency is located."""
    ways: dict[bool, list[tuple[float, str]]] = {True: [], False: []}  # behind the pose / ahead of it
    for ch, _regime, _words, r, lab, y, sigma in _timing_sensors(chans, resids, keep, reg):
        halves = [bin_margin(r[lab == v], sigma, y[lab == v], TIMING_Z) for v in (0, 2) if int((lab == v).sum()) >= 10]
        if len(halves) == 2 and halves[0][1] * halves[1][1] < 0:
            ways[halves[0][1] < 0].append((min(halves[0][0], halves[1][0]), ch.name))
    return _ring_margin(ways)


def scatter_finding(ch: Channel, resid: np.ndarray, keep: np.ndarray, reg: Regimes, t: np.ndarray) -> Finding | None:
    """A wheel whose residual is SCATTER_MIN noise levels RMS (and RELATIVE_MIN of the wheel's speed), or
    None; asked only of a wheel no bin located (compare), whose residual has no bias.  The regime named is
    the bin with the largest mean square, if it has SCATTER_REGIME times the whole's: a wheel that slips
    scatters most when the speed changes."""
    r = resid[keep]
    if ch.name not in WHEELS or r.size == 0:
        return None
    sigma = noise_level(ch, r)
    if _scatter_margin(r, sigma, ch.y[keep], ch.noise_floor) < 1.0:
        return None
    square = float((r * r).mean())
    if np.sqrt(square) < SCATTER_MIN * sigma:  # found against the encoder's rounding: say it in those terms
        sigma = ch.noise_floor
    whole = _rms_bin("", "all", r, sigma)
    bins = [whole]  # and every regime bin, for the report's picture
    for name, (labels, words) in reg.labels.items():
        if name.startswith(relevant_regimes(ch.name)):
            bins += [_rms_bin(text, f"{name}={value}", r[labels[keep] == value], sigma) for value, text in words.items()
                     if int((labels[keep] == value).sum()) >= 10]
    bins.sort(key=lambda b: -float(b["rms"]))  # type: ignore[arg-type]
    best = bins[0] if float(bins[0]["rms"]) ** 2 >= SCATTER_REGIME * square else whole  # type: ignore[arg-type]
    return Finding(ch.name, str(best["regime"]), str(best["key"]), spans(resid, keep, t, sigma, scatter=True),
                   float(best["mean"]), float(best["z"]), sigma, [best] + [b for b in bins if b is not best],
                   rms=float(best["rms"]))  # type: ignore[arg-type]


def scatter_margin(ch: Channel, resid: np.ndarray, keep: np.ndarray) -> float:
    """A wheel's residual RMS against its thresholds (SCATTER_MIN noise levels or SCATTER_FLOOR_MIN encoder
    roundings, and RELATIVE_MIN of the wheel's speed): scatter_finding locates it at 1 or more."""
    r = resid[keep]
    return _scatter_margin(r, noise_level(ch, r), ch.y[keep], ch.noise_floor) if r.size else 0.0


def _scatter_margin(r: np.ndarray, sigma: float, y: np.ndarray, floor: float) -> float:
    """The RMS against SCATTER_MIN noise levels or SCATTER_FLOOR_MIN encoder roundings (the nearer of the
    two: either witness is enough), and against RELATIVE_MIN of the wheel's speed (always)."""
    rms = float(np.sqrt((r * r).mean()))
    signal = RELATIVE_MIN * float(np.abs(y).mean())
    noise = max(rms / (SCATTER_MIN * sigma), rms / (SCATTER_FLOOR_MIN * max(floor, 1e-12)))
    return min(noise, rms / signal if signal > 0 else np.inf)


def lag_blocks(ch: Channel, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(change, sums), each (W, B): over blocks of LAG_BLOCK periods of the kept windows, the twin's change
    of speed across each block and the residual count summed over it.  A wheel late by L periods counts
    L times that change less.  Per period the firmware's speed loop feeds the encoder's rounding back into
    the commands, and so into the twin's speed (the twin's own firmware runs then seem to lead by a fifth
    of a period); summed over a block the rounding telescopes to its two ends."""
    r, y_hat = ch.residual()[keep], ch.y_hat[keep, 0]
    w, t = r.shape
    n = (t - 1) // LAG_BLOCK
    sums = r[:, 1:1 + n * LAG_BLOCK].reshape(w, n, LAG_BLOCK).sum(axis=-1)
    change = y_hat[:, LAG_BLOCK:1 + n * LAG_BLOCK:LAG_BLOCK] - y_hat[:, 0:n * LAG_BLOCK:LAG_BLOCK]
    return change, sums


def _lag_fit(ch: Channel, keep: np.ndarray) -> tuple[float, float, int]:
    """(lag in periods, > 0 late; its z; blocks): the blocks' residual sums regressed through the origin
    on the twin's change of speed (lag_blocks)."""
    change, sums = lag_blocks(ch, keep)
    sdd = float((change * change).sum())
    if sums.size == 0 or sdd <= 0:
        return 0.0, 0.0, 0
    beta = float((sums * change).sum()) / sdd
    scatter = float(((sums - beta * change) ** 2).mean())
    se = np.sqrt(max(scatter, ch.noise_floor ** 2) / sdd)  # a block's rounding: its two ends, sqrt(1/6) tick
    return -beta, -beta / se, sums.size


def _lag_judged(ch: Channel, keep: np.ndarray, period: float) -> tuple[float, float, int, float]:
    """(lag in periods, its z, blocks, margin) of _lag_fit's lag; the margin is the weaker of its
    thresholds (|z| >= Z_MIN, LAG_MIN_S), 0 for a channel other than a wheel or too few windows."""
    if ch.name not in WHEELS or int(keep.sum()) < SCALE_WINDOWS_MIN:
        return 0.0, 0.0, 0, 0.0
    lag, z, n = _lag_fit(ch, keep)
    return lag, z, n, min(abs(z) / Z_MIN, abs(lag) * period / LAG_MIN_S)


def lag_margin(ch: Channel, keep: np.ndarray, period: float) -> float:
    """A wheel's lag against its thresholds (_lag_judged): lag_finding locates it at 1 or more."""
    return _lag_judged(ch, keep, period)[3]


def lag_finding(ch: Channel, resid: np.ndarray, keep: np.ndarray, t: np.ndarray, period: float) -> Finding | None:
    """A wheel that answers the twin's speed changes late (or early), or None; asked only when no other
    rule located any channel of the drive (compare)."""
    lag, z, n, margin = _lag_judged(ch, keep, period)
    if margin < 1.0:
        return None
    sigma = noise_level(ch, resid[keep])
    mean = float(resid[keep].mean())
    return Finding(ch.name, LAG_REGIME, "lag", spans(resid, keep, t, sigma), mean, z, sigma,
                   [{"regime": LAG_REGIME, "key": "lag", "mean": mean, "z": z, "n": float(n)}], lag=lag * period)


def _rms_bin(regime: str, key: str, r: np.ndarray, sigma: float) -> dict[str, object]:
    rms = float(np.sqrt((r * r).mean()))
    return {"regime": regime, "key": key, "mean": float(r.mean()), "rms": rms, "z": rms / sigma, "n": float(r.size)}


def _scale_fit(ch: Channel, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(y, r, a, noise): the kept windows' recorded totals y and residual totals r, the proportional error
    a = (r . y) / (y . y) and the totals' noise: the larger of the scatter about r = a y and the noise of a
    window's two ends (TOTAL_NOISE per-period noise levels)."""
    y = ch.y[keep].sum(axis=1)
    r = y - ch.y_hat[keep, 0].sum(axis=1)
    syy = float(y @ y)
    a = float(r @ y) / syy if syy > 0 else 0.0
    floor = TOTAL_NOISE * noise_level(ch, ch.residual()[keep])
    scatter = float(((r - a * y) ** 2).sum()) / max(y.size - 1, 1)
    return y, r, a, float(np.sqrt(max(scatter, floor ** 2)))


def total_noise(ch: Channel, keep: np.ndarray) -> float:
    """How far a window's total may stray from a proportional error: what the fit weighs totals by.  The
    scatter counts what a window's start cannot say (a gear's play, a speed from rounded counts)."""
    return _scale_fit(ch, keep)[3]


def _scale_judged(ch: Channel, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float, float, float]:
    """(y, r, a, noise, z, margin) of _scale_fit's proportional error; the margin is the weaker of its
    thresholds (|z| >= Z_MIN, |a| >= SCALE_MIN, SCALE_MIN_COUNTS for a count), 0 when it is not judged:
    too few windows, or a robot that hardly turned (travelled), whose proportion is noise."""
    y, r, a, noise = _scale_fit(ch, keep)
    n, syy = y.size, float(y @ y)
    if n < SCALE_WINDOWS_MIN or np.sqrt(syy / max(n, 1)) < SCALE_SIGNAL_MIN * noise:
        return y, r, a, noise, 0.0, 0.0
    z = a / (noise / np.sqrt(syy))
    return y, r, a, noise, z, min(abs(z) / Z_MIN, abs(a) / (SCALE_MIN_COUNTS if ch.name in WHEELS else SCALE_MIN))


def scale_margin(ch: Channel, keep: np.ndarray) -> float:
    """A channel's proportional error over whole windows against its thresholds (_scale_judged):
    locate_scale locates it at 1 or more."""
    return _scale_judged(ch, keep)[5]


def locate_scale(ch: Channel, keep: np.ndarray, t: np.ndarray) -> Finding | None:
    """A proportional error of a channel summed over whole windows (channels.ACCUMULATED), or None.

    Each kept window's total, recorded y against the twin's: the residual r = y - y_hat regressed on y
    through the origin (_scale_fit), with a standard error from the totals' noise.
    """
    y, r, a, noise, z, margin = _scale_judged(ch, keep)
    if margin < 1.0:
        return None
    name, regime, n = ACCUMULATED[ch.name], SCALE_REGIME, y.size
    off = np.abs(r) > 2.0 * noise  # the windows where it shows beyond the noise
    found: list[tuple[float, float]] = []
    for w in np.flatnonzero(keep)[off]:
        a0, b0 = round(float(t[w, 0]), 2), round(float(t[w, -1]), 2)
        if found and a0 - found[-1][1] <= 2.5 * (t[w, 1] - t[w, 0]):  # back-to-back windows: one span
            found[-1] = (found[-1][0], b0)
        else:
            found.append((a0, b0))
    return Finding(name, regime, "scale", found, a, float(z), noise,
                   [{"regime": regime, "key": "scale", "mean": a, "z": float(z), "n": float(n)}])


def bin_margin(r: np.ndarray, sigma: float, y: np.ndarray, z_min: float = Z_MIN) -> tuple[float, float, float]:
    """(margin, mean, z) of a bin's residuals.  The margin is the weakest of the three tests, each as a
    ratio to its threshold (significant at z_min, large against the noise, large against the signal):
    at 1 or more the bin is a mismatch."""
    mean = float(r.mean())
    z = mean / (max(float(r.std()), sigma) / np.sqrt(r.size))
    signal = RELATIVE_MIN * float(np.abs(y).mean())
    margin = min(abs(z) / z_min, abs(mean) / (EFFECT_MIN * sigma), abs(mean) / signal if signal > 0 else np.inf)
    return margin, mean, z


def _bin_stats(r: np.ndarray, sigma: float, y: np.ndarray, z_min: float = Z_MIN) -> dict[str, float] | None:
    """Mean and z of a bin's residuals if they are a mismatch (bin_margin >= 1, on 10 or more), else None."""
    if r.size < 10:
        return None
    margin, mean, z = bin_margin(r, sigma, y, z_min)
    if margin < 1.0:
        return None
    return {"mean": mean, "z": z, "n": float(r.size)}


def spans(resid: np.ndarray, keep: np.ndarray, t: np.ndarray, sigma: float,
          scatter: bool = False) -> list[tuple[float, float]]:
    """Time spans (s) where the smoothed residual stays beyond EFFECT_MIN noise floors (its smoothed RMS
    beyond SCATTER_MIN, for a scatter)."""
    if not keep.any():
        return []
    period = float(np.median(np.diff(t[0]))) if t.shape[1] > 1 else 0.04
    width = max(1, int(round(SMOOTH_S / period)))
    kernel = np.ones(width) / width
    found: list[tuple[float, float]] = []
    for w in np.flatnonzero(keep):
        if scatter:
            hot = np.convolve(resid[w] ** 2, kernel, mode="same") >= (SCATTER_MIN * sigma) ** 2
        else:
            hot = np.abs(np.convolve(resid[w], kernel, mode="same")) >= EFFECT_MIN * sigma
        found += runs(hot, t[w])
    merged: list[tuple[float, float]] = []
    for a, b in sorted(found):
        if merged and a - merged[-1][1] <= 2.5 * period:
            merged[-1] = (merged[-1][0], max(b, merged[-1][1]))
        else:
            merged.append((a, b))
    return [(round(a, 2), round(b, 2)) for a, b in merged if b - a >= SPAN_MIN_S]


def runs(mask: np.ndarray, t: np.ndarray) -> list[tuple[float, float]]:
    """(t at a run's first row, t at the row after its last, or its last at the end) of each run of mask."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(float(t[a]), float(t[min(b, len(t) - 1)])) for a, b in zip(starts, ends)]


def ljung_box(resid: np.ndarray, lags: int = 10) -> tuple[float, float]:
    """(Q, p-value) of the Ljung-Box test on the residuals, windows pooled (autocorrelations within windows)."""
    r = resid - resid.mean(axis=1, keepdims=True)
    n_per = r.shape[1]
    lags = min(lags, n_per - 2)
    if lags < 1:
        return 0.0, 1.0
    denom = float((r * r).sum())
    if denom == 0.0:
        return 0.0, 1.0
    n = r.size
    q = 0.0
    for k in range(1, lags + 1):
        rho = float((r[:, k:] * r[:, :-k]).sum()) / denom
        q += rho * rho / (n - k * r.shape[0])
    q *= n * (n + 2)
    return q, float(stats.chi2.sf(q, lags))


def input_lag(resid: np.ndarray, u: np.ndarray, max_lag: int = 10) -> tuple[int, float]:
    """(lag, correlation) of the largest cross-correlation between residual and input changes, lags 0..max_lag."""
    du = np.diff(u, axis=1, prepend=u[:, :1])
    best = (0, 0.0)
    for k in range(0, min(max_lag, resid.shape[1] - 2) + 1):
        a = resid[:, k:].ravel()
        b = du[:, : du.shape[1] - k].ravel()
        if a.std() == 0 or b.std() == 0:
            continue
        c = float(np.corrcoef(a, b)[0, 1])
        if abs(c) > abs(best[1]):
            best = (k, c)
    return best
