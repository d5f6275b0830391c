"""Fit and choose: which effects of the library explain the located mismatch, and how large they are.

Candidates at the sites the located channels point to are screened in one batch run, the most promising
fitted by bounded least squares on the training windows, and chosen by forward selection (F test, held-out
gain, BIC) then backward elimination.  The rules and their thresholds: docs/diagnosis.md, "Name and fit".
"""
from __future__ import annotations

import copy
import dataclasses
import math
import multiprocessing
import signal
from collections import OrderedDict
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import optimize, stats

from host_sim.physics import effects as E
from host_sim.diagnosis.channels import (ACCUMULATED, AMBIENT, IR, MOTION, WHEELS, Channel, build_channels,
                                        drive_channel, drive_located, judged_windows, located_sensors,
                                        sensor_channel, sensor_channels)
from host_sim.diagnosis.tolerance import Tolerance, relative_bounds
from host_sim.diagnosis.windows import WindowRun, Windows, by_step_parts, run_key, run_windows
from host_sim.physics.params import DEFAULT, RobotParams
from host_sim.recordings.recording import Recording
from host_sim.physics.world import World

MAX_EFFECTS = 3
# The channels whose window totals the fit adds (travel, turn).  A wheel's count only once located
# (fit_totals): a window's count carries its start's speed error, which the periods judge well enough.
FITTED_TOTALS = ("forward", "heading_rate")
SHORTLIST = 4  # candidates fitted in full after screening
RUNS_KEPT = 16  # window runs an objective keeps, the newest: an IR effect's fit beside a located drive tries
# twins that differ in their sensors alone, whose run is the one before
MIN_SHARE = 16  # robots: a batch's own cost (its steps in Python) is about that many robots', so workers share
# no smaller pieces of one (tests/test_diagnosis.py::test_workers_share_a_large_batch_in_runs_of_neighbours)
WITHIN_NOISE = 1.0  # held-out cost per weighted residual below which no further effect is sought
SCREEN_STEPS = (0.02, 0.05, 0.1, 0.2, 0.35, 0.6)  # of the span from a one-parameter effect's start to each bound:
# the values the screening also tries outright, about 2x apart, since a dry friction's cost has a valley about
# 2x wide.  Tested: tests/test_diagnosis.py::
# test_screening_tries_each_effect_about_twice_as_far_each_time_then_zooms_in_on_the_best
ZOOM_POINTS = 8  # values between a shortlisted effect's best trial and its neighbours, tried before its fit
LOG_TRIALS = 8  # a range with 0 < lower <= upper / 10 is tried at lower * (upper / lower) ** (k / 8), k = 1..7: a
# grip's cost has a narrow valley, and trials spaced evenly would step over it
P_MAX = 1e-4  # F test against the twin without the effect
MIN_HELD_OUT_GAIN = 0.10  # relative drop of the held-out weighted sum of squares
MIN_LOCATED_GAIN = 0.30  # or of the located channels' part of it alone
START_INSIDE = 0.01  # of a parameter's range: how far inside its bounds a fit starts
FIT_FTOL = 1e-4  # a fit ends when a step lowers its cost by less than this share of it: a BIC change of n 1e-4,
# under TIE_BIC for the ~9000 residuals of a 90 s recording; scipy's 1e-8 goes on stepping where nothing more is
# to be had (tests/test_diagnosis.py::test_a_fit_ends_once_its_steps_gain_little)
FIT_XTOL = 1e-4  # and when the steps it tries shrink below this share of its parameters (in their ranges): on a
# rough cost (a gear's play, a slippery twin) most steps are refused, each shrinking the next 4x, and scipy's
# 1e-8 goes on refusing to move a value by under a millionth of its range
# (tests/test_diagnosis.py::test_a_fit_stops_once_the_steps_it_tries_are_tiny)
TIE_BIC = 2.0  # a BIC difference below this is no evidence either way (Kass & Raftery 1995)
AMBIGUITY = 0.02  # held-out costs within 2 % of the chosen one: "explains it equally well"
DRIVE_EFFECTS = E.names_of_kind("drive", "robot")  # the library's order, plainest first: ties go to it
SENSOR_EFFECTS = E.names_of_kind("sensor")
RING_EFFECTS = E.names_of_kind("ring")
LEAK_DISTINCT_COUNTS = 3.0  # counts (one reading's noise): a leak that varies less over the recording is a constant
LEAK_STRONG_BIC = 10.0  # BIC by which such a leak must beat the sensor's offset to be named (Kass & Raftery)
AMBIENT_SMOOTH_S = 0.5  # s: the ambient light is judged on a running mean (the readings' own noise is not light)
# The build's values an effect is fitted beside, each within its band of the datasheet (the objective's
# tolerance): a battery's resistance sags the reading by R (i_e + P / V) below the pack's open-circuit voltage,
# which a real pack holds anywhere in its band (its charge); held at the datasheet's, the resistance is fitted
# to that offset instead (tests/test_diagnosis.py::test_a_battery_resistance_is_fitted_beside_the_packs_own_voltage).
COMPANIONS: dict[str, tuple[str, ...]] = {"battery_resistance": ("battery_voltage",)}


@dataclass(frozen=True)
class Candidate:
    name: str
    site: str | int

    def label(self) -> str:
        return f"{self.name}({self.site})" if self.site != "both" else self.name


@dataclass
class Model:
    """A twin: nominal parameters plus chosen effects, with their values and how well it does."""

    effects: list[Candidate]
    values: list[list[float]]
    params: RobotParams
    cost_train: float
    cost_test: float
    n_train: int
    ci95: list[list[tuple[float, float]]] = field(default_factory=list)
    p_value: float = 1.0
    alternatives: list[str] = field(default_factory=list)
    rivals: list[Model] = field(default_factory=list)  # the models of the alternatives (their newest effect swapped)
    r_test: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the held-out weighted residuals
    located_gain: float = 0.0  # what its newest effect removed of the located channels' held-out residuals
    build: dict[str, float] = field(default_factory=dict)  # the companions fitted beside its effects (COMPANIONS)


def candidates_for(channels: list[str], drive: str = "current", bench: bool = False) -> list[Candidate]:
    """The library's effects that may explain these channels, those it offers for the robot's drive and,
    on a bench, none of the floor's or the body's (effects.offered)."""
    out: list[Candidate] = []
    if drive_located(channels):
        for name in DRIVE_EFFECTS:
            if E.offered(name, drive, bench):
                out += [Candidate(name, s) for s in E.LIBRARY[name].sites()]
    sensors = located_sensors(channels)
    for k in sensors:
        out += [Candidate(name, k) for name in SENSOR_EFFECTS]
    if sensors:
        out += [Candidate(name, "both") for name in RING_EFFECTS]
    return out


def reach(cand: Candidate) -> frozenset[str | int]:
    """Where an effect acts: its IR pair (0..7), all eight (a ring effect), or the drive (a wheel's effect or
    the whole robot's)."""
    kind = E.LIBRARY[cand.name].kind
    if kind == "sensor":
        return frozenset({cand.site})
    return frozenset(range(8)) if kind == "ring" else frozenset({"drive"})


def places(channels: list[str]) -> set[str | int]:
    """Where these channels point: the drive, and each IR pair (0..7) of theirs."""
    out: set[str | int] = set(located_sensors(channels))
    return out | ({"drive"} if drive_located(channels) else set())


def rivals(best: Model, tried: list[Model]) -> list[Model]:
    """The tried models that explain it equally well (held-out cost within AMBIGUITY of best's) with an effect
    acting where best's does: one acting elsewhere removes another part of the mismatch, not this one
    (tests/test_diagnosis.py::test_a_rival_acts_where_the_chosen_effect_does)."""
    where = reach(best.effects[-1])
    return [m for m in tried if m is not best and m.cost_test <= best.cost_test * (1 + AMBIGUITY)
            and reach(m.effects[-1]) & where]


def objective_channels(channels: list[str], available: list[str]) -> list[str]:
    """The channels a fit is judged on: the located ones and their family."""
    wanted: set[str] = set()
    for c in channels:
        if drive_channel(c):
            wanted |= set(WHEELS) | set(MOTION) | {"vbat"}
        elif sensor_channel(c):
            k = int(c.split("_")[1])
            wanted |= {IR[k], AMBIENT[k]}
    return [c for c in available if c in wanted]


class Objective:
    """Weighted residuals of the chosen channels, on the training and the held-out windows, for many twins."""

    def __init__(self, rec: Recording, windows: Windows, world: World | None, names: list[str],
                 sigma: dict[str, float], contact: np.ndarray, unjudged: np.ndarray | None = None,
                 totals: tuple[str, ...] = FITTED_TOTALS) -> None:
        self.rec, self.world = rec, world
        # Only the windows judged are simulated: the drive's channels are not fitted on those touching a
        # wall, the sensors' are (channels.judged_windows).
        judged = {name: judged_windows(name, contact) for name in names}
        keep = np.any(list(judged.values()), axis=0) if names else ~contact
        self.unjudged = unjudged[keep] if unjudged is not None else None
        self.windows = windows.select(keep)
        self.rows = {name: rows[keep] for name, rows in judged.items()}  # each channel's windows, of those kept
        self.names = names
        self.sigma = sigma
        self.totals = totals  # the channels whose window totals are residuals too (fit_totals)
        self.train = ~self.windows.held_out
        self.test = self.windows.held_out
        self.sensors = any(sensor_channel(n) for n in names)
        self.sensors_only = bool(names) and all(sensor_channel(n) for n in names)  # then no physics to run
        self.evaluations = 0
        self.workers: Executor | None = None  # processes that share the work (select's, while it runs)
        self.worker_count = 1  # how many
        self.test_columns: dict[str, np.ndarray] = {}  # channel (or window total) -> its held-out residuals' columns
        self.train_windows = np.zeros(0, dtype=int)  # each training residual's window: the intervals' clusters
        self.clustered_intervals = False  # window-clustered sandwich intervals (with a test block) or the Jacobian's
        self.tolerance: Tolerance | None = None  # the datasheet's: an effect within it is the robot as built
        self.kept: OrderedDict[tuple[str, str], WindowRun] = OrderedDict()  # (part, run_key) -> its run, newest last

    def residuals(self, robots: list[RobotParams], part: str = "both") -> tuple[np.ndarray, np.ndarray]:
        """(train (N, n), test (N, m)) weighted residuals of N twins: with workers (select), the robots
        grouped by step parts (windows.by_step_parts), cut into shares (worker_shares), in processes of their
        own; a robot's figures do not depend on the others in its batch.
        part: "train" or "test" runs those windows alone (the other comes back with no columns): each
        window's twin starts on its own, so its residuals are the same either way.
        A twin asked for twice runs once: the screening asks for the current model again as each candidate's
        start (tests/test_diagnosis.py::test_a_twin_asked_for_twice_in_one_batch_runs_once)."""
        distinct, where = _distinct(robots)
        if len(distinct) < len(robots):
            train, test = self.residuals(distinct, part)
            return train[where], test[where]
        workers = self.workers
        groups = (worker_shares(by_step_parts(robots), self.worker_count)
                  if workers is not None and not self.sensors_only else [])
        if workers is not None and len(groups) > 1:
            self.evaluations += len(robots)
            parts = list(workers.map(_residuals_in_worker, [[robots[i] for i in ix] for ix in groups],
                                     [part] * len(groups), [self.sigma] * len(groups)))
            order = np.argsort(np.concatenate(groups))
            return (np.concatenate([train for train, _test in parts])[order],
                    np.concatenate([test for _train, test in parts])[order])
        return self.residuals_here(robots, part)

    def residuals_here(self, robots: list[RobotParams], part: str = "both") -> tuple[np.ndarray, np.ndarray]:
        """residuals, in this process."""
        self.evaluations += len(robots)
        if part not in ("both", "train", "test"):
            raise ValueError(f"part must be 'both', 'train' or 'test', not {part!r}")
        run_these = np.ones(len(self.windows), dtype=bool) if part == "both" else (
            self.train if part == "train" else self.test)
        if not run_these.any():
            return np.zeros((len(robots), 0)), np.zeros((len(robots), 0))
        windows = self.windows.select(run_these)
        unjudged = self.unjudged[run_these] if self.unjudged is not None else None
        if self.sensors_only:  # the sensors read the recorded track: the twin's motion does not enter them
            assert self.world is not None
            chans = {c.name: c for c in sensor_channels(self.rec, windows.index[:, 1:], robots, self.world,
                                                        unjudged)}
        else:
            run = self._runs(part, windows, robots)
            chans = {c.name: c for c in build_channels(self.rec, windows, run, robots,
                                                        self.world if self.sensors else None, unjudged)}
        train_w, test_w = self.train[run_these], self.test[run_these]
        train, test, groups = [], [], []
        window_ids = np.flatnonzero(run_these)  # each run window's index among self.windows
        at = 0
        for name in self.names:
            c: Channel = chans[name]
            r = (c.y[:, None, :] - c.y_hat) / self.sigma[name]  # (W, N, T')
            periods = r.shape[-1]
            if name in self.totals:
                # Each window's travel and turn too: a radius or a track a few % off is below the tracker's
                # noise in any one period and above it over a window (locate.locate_scale).
                total = (c.y.sum(axis=-1)[:, None] - c.y_hat.sum(axis=-1)) / self.sigma[ACCUMULATED[name]]
                r = np.concatenate([r, total[..., None]], axis=-1)
            rows = self.rows[name][run_these]
            train.append(r[train_w & rows].transpose(1, 0, 2).reshape(len(robots), -1))
            groups.append(np.repeat(window_ids[train_w & rows], r.shape[-1]))
            test.append(r[test_w & rows].transpose(1, 0, 2).reshape(len(robots), -1))
            if part != "train":
                cols = at + np.arange(test[-1].shape[1]).reshape(-1, r.shape[-1])  # (held-out windows, T' [+ 1])
                self.test_columns[name] = cols[:, :periods].ravel()
                if name in self.totals:
                    self.test_columns[ACCUMULATED[name]] = cols[:, periods]
                at += test[-1].shape[1]
        if part != "test":
            self.train_windows = np.concatenate(groups)
        return np.concatenate(train, axis=1), np.concatenate(test, axis=1)

    def _runs(self, part: str, windows: Windows, robots: list[RobotParams]) -> WindowRun:
        """The robots' window runs (on `part`'s windows), one per run_key: a batch of new twins, each its own, runs
        as it is; kept are the newest RUNS_KEPT of batches that small, as a fit's steps are
        (tests/test_diagnosis.py::test_a_twin_that_differs_in_its_sensors_alone_is_run_once)."""
        keys = [(part, run_key(p)) for p in robots]
        first: dict[tuple[str, str], RobotParams] = {}
        for k, p in zip(keys, robots):
            if k not in self.kept:
                first.setdefault(k, p)
        if len(first) == len(robots):
            run = run_windows(self.rec, windows, robots, self.world)
            if len(robots) > RUNS_KEPT:
                return run  # a screening's batch: nothing to share, and too many to keep
            self._keep(keys, run)
        else:
            if first:
                self._keep(list(first), run_windows(self.rec, windows, list(first.values()), self.world))
            runs = [self.kept[k] for k in keys]
            run = WindowRun(*(np.concatenate([getattr(r, f) for r in runs], axis=1) for f in ("enc", "pose", "vbat")))
        for k in keys:
            self.kept.move_to_end(k)
        while len(self.kept) > RUNS_KEPT:
            self.kept.popitem(last=False)
        return run

    def _keep(self, keys: list[tuple[str, str]], run: WindowRun) -> None:
        """Keep each robot j of run as keys[j]'s."""
        assert run.vbat is not None
        for j, k in enumerate(keys):
            self.kept[k] = WindowRun(run.enc[:, j:j + 1], run.pose[:, j:j + 1], run.vbat[:, j:j + 1])

    def located_gain(self, before: np.ndarray, after: np.ndarray, located: list[str]) -> float:
        """1 - the held-out sum of squares after / before, on the located channels' columns alone, of those
        the change moves: a drive effect leaves a sensor's residuals as they were (the sensors read the
        recorded track), and they would only dilute its gain
        (tests/test_diagnosis.py::test_a_located_channel_an_effect_leaves_unchanged_does_not_dilute_its_located_gain)."""
        cols = [self.test_columns[c] for c in located if c in self.test_columns]
        cols = [c for c in cols if not np.array_equal(before[c], after[c])]
        if not cols:
            return 0.0
        pick = np.concatenate(cols)
        ss0 = float(before[pick] @ before[pick])
        return 1.0 - float(after[pick] @ after[pick]) / ss0 if ss0 > 0 else 0.0


def _distinct(robots: list[RobotParams]) -> tuple[list[RobotParams], np.ndarray]:
    """(the robots without repeats, in order of first appearance; for each robot its index among them).
    Keyed by repr, whose floats round-trip exactly (0.0 and -0.0 apart), not by ==."""
    first: dict[str, int] = {}
    where = np.array([first.setdefault(repr(p), len(first)) for p in robots], dtype=int)
    if len(first) == len(robots):
        return robots, where
    keep = np.unique(where, return_index=True)[1]
    return [robots[i] for i in keep], where


def worker_shares(groups: list[list[int]], workers: int) -> list[list[int]]:
    """Groups of robots cut so that none holds more than its share of them all (1 / workers), largest first,
    for the workers to take in turn: on a slippery floor or with a gear's play, nearly all of a screening's
    robots share one set of step parts (tests/test_diagnosis.py::test_workers_share_a_large_batch_in_runs_of_neighbours)."""
    share = max(-(-sum(len(ix) for ix in groups) // max(workers, 1)), MIN_SHARE)
    # in runs of neighbours, not every n-th robot: a batch steps as its dearest robot needs, and neighbours
    # are one candidate's values, which step alike
    pieces = [[int(i) for i in piece] for ix in groups for piece in np.array_split(ix, -(-len(ix) // share))]
    return sorted(pieces, key=len, reverse=True)


def fit_totals(located: list[str]) -> tuple[str, ...]:
    """The channels whose window totals a fit adds: the travel and the turn, and a wheel's count once
    located (an encoder 3.7 % fine showed as 1.4 % more counts a window, the firmware's loop taking back
    the rest, well below any one period's quantisation)."""
    return FITTED_TOTALS + tuple(w for w in WHEELS if ACCUMULATED[w] in located)


def _apply_all(base: RobotParams, effects: list[Candidate], values: list[list[float]]) -> RobotParams:
    p = base
    for cand, v in zip(effects, values):
        p = E.apply(p, cand.name, cand.site, v)
    return p


def fit_model(obj: Objective, base: RobotParams, effects: list[Candidate], start: list[list[float]],
              companions: tuple[str, ...] | None = None) -> Model:
    """Bounded least squares of the effects' parameters on the training windows, with the build's values
    fitted beside them (companions: by default those of the effects, COMPANIONS)."""
    comp = _companions(obj, effects) if companions is None else companions
    nc = len(comp)
    sizes = [len(E.LIBRARY[c.name].params) for c in effects]
    lo_c, hi_c = _companion_bounds(obj, comp)
    lo_e, hi_e = _bounds(effects, base)
    lo, hi = np.concatenate([lo_c, lo_e]), np.concatenate([hi_c, hi_e])
    inside = START_INSIDE * (hi_c - lo_c)
    x0 = np.concatenate([np.clip([float(getattr(base, f)) for f in comp], lo_c + inside, hi_c - inside),
                         fit_start(effects, start, base)])
    step = 1e-3 * (hi - lo)

    def unpack(x: np.ndarray) -> list[list[float]]:
        out, i = [], nc
        for n in sizes:
            out.append([float(v) for v in x[i:i + n]])
            i += n
        return out

    def robot(x: np.ndarray) -> RobotParams:
        return _apply_all(_built(base, comp, x), effects, unpack(x))

    cache: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        key = x.tobytes()
        if key not in cache:
            # One batch: the twin at x and at x nudged along every parameter (away from the nearer bound).
            h = np.where(x + step <= hi, step, -step)
            points = [x] + [x + np.eye(len(x))[i] * h[i] for i in range(len(x))]
            train, test = obj.residuals([robot(pt) for pt in points])
            jac = ((train[1:] - train[0]) / h[:, None]).T
            cache.clear()
            cache[key] = (train[0], jac, test[0])
        return cache[key]

    sol = optimize.least_squares(lambda x: evaluate(x)[0], x0, jac=lambda x: evaluate(x)[1], bounds=(lo, hi),
                                 x_scale=hi - lo, max_nfev=30, ftol=FIT_FTOL, xtol=FIT_XTOL)
    r_train, jac, r_test = evaluate(sol.x)
    model = Model(list(effects), unpack(sol.x), robot(sol.x), float(r_train @ r_train), float(r_test @ r_test),
                  int(r_train.size), r_test=r_test, build={f: float(v) for f, v in zip(comp, sol.x)})
    blocks = [1] * nc + sizes
    model.ci95 = (sandwich_intervals(sol.x, jac, r_train, blocks, lo, hi, touching_runs(obj.windows, obj.train_windows))
                  if obj.clustered_intervals else _intervals(sol.x, jac, r_train, blocks, lo, hi))[nc:]
    return model


def _companions(obj: Objective, effects: list[Candidate]) -> tuple[str, ...]:
    """The build's values fitted beside these effects: their COMPANIONS that the objective's tolerance bands."""
    tol = getattr(obj, "tolerance", None)
    if tol is None:
        return ()
    return tuple(dict.fromkeys(f for c in effects for f in COMPANIONS.get(c.name, ()) if tol.bands.get(f, 0.0) > 0))


def _built(p: RobotParams, comp: tuple[str, ...], values: np.ndarray) -> RobotParams:
    """p with each companion's field at its value (the first len(comp) of values)."""
    return p.replace(**{f: float(v) for f, v in zip(comp, values)}) if comp else p


def _companion_bounds(obj: Objective, comp: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Each companion's band about the datasheet's value (tolerance.relative_bounds, as the calibration's; a
    companion is a datasheet field, relative to its value, none of tolerance.ABSOLUTE)."""
    if not comp:
        return np.zeros(0), np.zeros(0)
    tol = obj.tolerance
    assert tol is not None  # _companions gives none without it
    nominal = np.array([float(getattr(tol.datasheet, f)) for f in comp])
    lo, hi = relative_bounds(list(comp), np.array([tol.bands[f] for f in comp]))
    return nominal * (1.0 + lo), nominal * (1.0 + hi)


def fit_apart(obj: Objective, base: RobotParams, model: Model, keep: np.ndarray) -> Model:
    """model's effects fitted again, from its values, on the windows `keep` ((W,) bool of obj's) alone: a
    half of the recording, to see whether a parameter changes during it (report, verdict.changed)."""
    part = copy.copy(obj)
    part.windows, part.train, part.test = obj.windows.select(keep), obj.train[keep], obj.test[keep]
    part.rows = {name: rows[keep] for name, rows in obj.rows.items()}
    part.unjudged = obj.unjudged[keep] if obj.unjudged is not None else None
    part.workers, part.test_columns = None, {}
    return fit_model(part, base, model.effects, model.values)


def _bounds(effects: list[Candidate], base: RobotParams) -> tuple[np.ndarray, np.ndarray]:
    """The fit's bounds: the library's, narrowed to what base's parameter checks admit (E.bounds)."""
    if not effects:
        return np.zeros(0), np.zeros(0)
    return (np.concatenate([E.bounds(c.name, base)[0] for c in effects]),
            np.concatenate([E.bounds(c.name, base)[1] for c in effects]))


def fit_start(effects: list[Candidate], start: list[list[float]], base: RobotParams = DEFAULT) -> np.ndarray:
    """Where a fit of these effects from `start` really starts: a little inside the bounds.  scipy's trust
    region starts with a radius in proportion to x0 (scaled), so a start on a bound of 0 (an absent latency,
    backlash, drag...) would never leave it."""
    lo, hi = _bounds(effects, base)
    inside = START_INSIDE * (hi - lo)
    return np.clip(np.array([v for values in start for v in values], dtype=float), lo + inside, hi - inside)


def touching_runs(windows: Windows, which: np.ndarray) -> np.ndarray:
    """For each entry of `which` (indices of windows), the run of back-to-back windows it lies in: a window's
    lead-in replays the rows that end the window before, so the two twins' errors are not independent (their
    scores correlate about -0.5); a window not among `which` between them (a held-out one) parts them
    (tests/test_verdict.py::test_windows_that_touch_are_one_cluster)."""
    if which.size == 0:
        return which
    ids = np.unique(which)
    starts = windows.start[ids]
    run = np.concatenate([[0], np.cumsum(np.diff(starts) > windows.rows)])
    return run[np.searchsorted(ids, which)]


def _intervals(x: np.ndarray, jac: np.ndarray, r: np.ndarray, sizes: list[int], lo: np.ndarray,
               hi: np.ndarray) -> list[list[tuple[float, float]]]:
    """95 % intervals from the Jacobian, widened for the residuals' correlation along each window (the
    default; a diagnosis with a test block uses sandwich_intervals)."""
    n, k = jac.shape
    s2 = float(r @ r) / max(n - k, 1)
    rho = float(np.corrcoef(r[:-1], r[1:])[0, 1]) if n > 2 and r.std() > 0 else 0.0
    inflate = (1 + max(rho, 0.0)) / (1 - min(max(rho, 0.0), 0.95))
    try:
        cov = np.linalg.pinv(jac.T @ jac) * s2 * inflate
        half = 1.96 * np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        half = np.full(k, np.inf)
    return _around(x, half, sizes, lo, hi)


def _around(x: np.ndarray, half: np.ndarray, sizes: list[int], lo: np.ndarray,
            hi: np.ndarray) -> list[list[tuple[float, float]]]:
    """x +- half, within the bounds, one list per effect."""
    out, i = [], 0
    for size in sizes:
        out.append([(float(max(lo[j], x[j] - half[j])), float(min(hi[j], x[j] + half[j]))) for j in range(i, i + size)])
        i += size
    return out


def sandwich_intervals(x: np.ndarray, jac: np.ndarray, r: np.ndarray, sizes: list[int], lo: np.ndarray,
                       hi: np.ndarray, windows: np.ndarray, prior: np.ndarray | None = None
                       ) -> list[list[tuple[float, float]]]:
    """95 % intervals from a cluster-robust sandwich, a run of touching windows the cluster (touching_runs):
    (J'J)^-1 (sum over clusters of J_g' r_g r_g' J_g) (J'J)^-1 G / (G - 1), with a t quantile on G - 1
    degrees of freedom (G clusters).  The residuals within a window are correlated (a start state, a speed
    loop), and the twin's own error is in them; apart runs are close to independent, so they carry the
    evidence (tests/test_verdict.py::test_the_intervals_hold_the_true_value_about_95_times_in_100).
    prior: a prior's information (k, k), added to the bread (calibrate.refit_jointly's nuisances)."""
    k = jac.shape[1]
    ids, group = np.unique(windows, return_inverse=True) if windows.size == r.size else (np.zeros(1), np.zeros(r.size, int))
    g = len(ids)
    scores = np.zeros((g, k))
    np.add.at(scores, group, jac * r[:, None])  # each window's J_w' r_w
    try:
        bread = np.linalg.pinv(jac.T @ jac + (prior if prior is not None else 0.0))
        cov = bread @ (scores.T @ scores) @ bread * (g / max(g - 1, 1))
        half = float(stats.t.isf(0.025, max(g - 1, 1))) * np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        half = np.full(k, np.inf)
    return _around(x, half, sizes, lo, hi)


def f_test(rss0: float, rss1: float, k: int, n: int, k_total: int) -> float:
    if rss1 <= 0 or n <= k_total:
        return 0.0 if rss0 > rss1 else 1.0
    f = ((rss0 - rss1) / k) / (rss1 / (n - k_total))
    return float(stats.f.sf(f, k, n - k_total)) if f > 0 else 1.0


def bic(model: Model) -> float:
    k = sum(len(v) for v in model.values)
    n = max(model.n_train, 1)
    return n * math.log(max(model.cost_train, 1e-300) / n) + k * math.log(n)


def screen(obj: Objective, base: RobotParams, current: Model, cands: list[Candidate],
           keep: int, located: list[str] | None = None) -> list[tuple[Candidate, list[float]]]:
    """The `keep` candidates that promise the lowest training cost, and the most promising at each place the
    located channels point to (places) that none of those acts on (reach), each with where its fit should start.

    One batch run: the current model plus each candidate at its absent value, nudged, and at a few
    trial values across its range (screen_trials).  A candidate's promise is the best of one
    Gauss-Newton step from absent and its trials: effects with a threshold (a gear's play, a delay)
    barely change the residuals near absent, so the linear step alone would screen them out.  The fit
    starts where that best was, not at absent: a grip (traction_limit) at its nominal value never
    slips, so a fit started there sees no gradient and stays; and where a trial was best, from the best
    of a few values around it (zoom).  One with companions the current twin has not fitted (COMPANIONS) takes
    its step along them too, and is fitted as screened: alone, its cost may rise every way while the build's
    value beside it stands where it is.
    """
    robots = [current.params]
    slots, joint = [], set()
    for cand in cands:
        comp = tuple(f for f in _companions(obj, [cand]) if f not in current.build)
        lo_c, hi_c = _companion_bounds(obj, comp)
        lo_e, hi_e = (np.array(b) for b in E.bounds(cand.name, base))
        lo, hi = np.concatenate([lo_e, lo_c]), np.concatenate([hi_e, hi_c])
        x0 = np.concatenate([_start_values(base, cand), [float(getattr(current.params, f)) for f in comp]])
        n = len(x0) - len(comp)

        def robot(x: np.ndarray, cand: Candidate = cand, comp: tuple[str, ...] = comp, n: int = n) -> RobotParams:
            return E.apply(_built(current.params, comp, x[n:]), cand.name, cand.site, list(x[:n]))

        h = np.where(x0 + 1e-2 * (hi - lo) <= hi, 1e-2 * (hi - lo), -1e-2 * (hi - lo))
        first = len(robots)
        robots.append(robot(x0))
        robots += [robot(x0 + np.eye(len(x0))[i] * h[i]) for i in range(len(x0))]
        trials = [] if comp else screen_trials(cand.name, float(x0[0]), base)
        robots += [E.apply(current.params, cand.name, cand.site, [x]) for x in trials]
        slots.append((first, x0, h, lo - x0, hi - x0, trials, n))
        if comp:
            joint.add(cand)
    train, _test = obj.residuals(robots, part="train")
    predicted, starts, seen = [], [], []
    for first, x0, h, dlo, dhi, trials, n in slots:
        r0 = train[first]
        jac = ((train[first + 1:first + 1 + len(h)] - r0) / h[:, None]).T
        step, *_ = np.linalg.lstsq(jac, -r0, rcond=None)
        step = np.clip(step, dlo, dhi)
        resid = r0 + jac @ step
        tried = train[first + 1 + len(h):first + 1 + len(h) + len(trials)]
        costs = [float(resid @ resid)] + [float(r @ r) for r in tried]
        best = int(np.argmin(costs))
        starts.append(list(x0[:n] + step[:n]) if best == 0 else [trials[best - 1]])
        predicted.append(costs[best])
        # the values tried outright, with their actual costs, for zoom
        seen.append(sorted([(float(x0[0]), float(r0 @ r0))] + [(x, c) for x, c in zip(trials, costs[1:])]))
    picked = _each_place(cands, predicted, keep, located or [], float(train[0] @ train[0]))
    chosen = [(cands[i], starts[i], seen[i]) for i in picked]
    zoomed = dict(zoom(obj, base, current, [entry for entry in chosen if entry[0] not in joint]))
    return [(cand, start if cand in joint else zoomed[cand]) for cand, start, _seen in chosen
            if cand in joint or cand in zoomed]


def _each_place(cands: list[Candidate], predicted: list[float], keep: int, located: list[str], cost: float
                ) -> list[int]:
    """The `keep` candidates of lowest predicted cost, then the lowest at each place still located (places) that
    none of those acts on (reach), if it promises any gain (under `cost`, the current twin's): an IR pair's gain
    promises less than a wheel's many effects, each more than it, and would never be fitted; a place no longer
    located is left, its fit would be of noise
    (tests/test_diagnosis.py::test_each_located_place_keeps_its_most_promising_effect)."""
    order = [int(i) for i in np.argsort(predicted)]
    picked, wanted = order[:keep], places(located)
    for i in order[keep:]:
        if reach(cands[i]) & wanted and reach(cands[i]) not in {reach(cands[j]) for j in picked} and predicted[i] < cost:
            picked.append(i)
    return picked


def zoom(obj: Objective, base: RobotParams, current: Model,
         shortlist: list[tuple[Candidate, list[float], list[tuple[float, float]]]]
         ) -> list[tuple[Candidate, list[float]]]:
    """Each shortlisted one-parameter effect whose best screening value was a trial starts its fit from the
    best of ZOOM_POINTS more values between that trial's neighbours (one batch run for all): a gear's play
    or a latency has a rough cost, and a fit stays in the dip it starts in
    (tests/test_diagnosis.py::test_screening_tries_each_effect_about_twice_as_far_each_time_then_zooms_in_on_the_best).

    One whose start is the linear step's (a promise, not a cost) is tried where its fit would start, in the
    same run.  If that costs no less than the twin without it, nor does any value the screening tried, it
    is not fitted: its cost rises every way the screening looked, and a fit from there only climbs back
    down towards absent, at a high price on a slippery twin
    (tests/test_diagnosis.py::test_an_effect_whose_cost_rises_every_way_the_screening_looked_is_not_fitted).
    More parameters are fitted as screened: a linear step along several can overshoot and still lead the
    fit to the value."""
    robots, grids = [], []
    for cand, start, seen in shortlist:
        xs = [x for x, _c in seen]
        if len(start) != 1:
            grids.append([])
        elif start[0] not in xs:  # a linear step's start
            grids.append([float(fit_start([cand], [start], base)[0])])
        else:
            k = xs.index(start[0])
            lo, hi = xs[max(k - 1, 0)], xs[min(k + 1, len(xs) - 1)]
            grid = (np.geomspace(lo, hi, ZOOM_POINTS + 2) if lo > 0 and E.bounds(cand.name, base)[0][0] > 0
                    else np.linspace(lo, hi, ZOOM_POINTS + 2))[1:-1]
            grids.append([float(x) for x in grid if x != start[0]])
        robots += [E.apply(current.params, cand.name, cand.site, [x]) for x in grids[-1]]
    if not robots:
        return [(cand, start) for cand, start, _seen in shortlist]
    train, _test = obj.residuals(robots, part="train")
    out, at = [], 0
    for (cand, start, seen), values in zip(shortlist, grids):
        costs = [float(r @ r) for r in train[at:at + len(values)]]
        at += len(values)
        if len(start) == 1 and start[0] not in dict(seen):  # a linear step's start, now tried
            without = dict(seen)[_start_values(base, cand)[0]]  # in the screening's batch, as the others
            if min(costs + [c for _x, c in seen]) >= without:
                continue
        elif costs and min(costs) < dict(seen)[start[0]]:  # zoomed round a trial, whose cost was seen
            start = [values[int(np.argmin(costs))]]
        out.append((cand, start))
    return out


def screen_trials(name: str, start: float, base: RobotParams = DEFAULT) -> list[float]:
    """The values of a one-parameter effect the screening tries outright (none for more parameters): in even
    ratios across a range of orders of magnitude, else SCREEN_STEPS of the way from its start to each bound."""
    (lo, *more), (hi, *_) = E.bounds(name, base)
    if more:
        return []
    if 0 < lo <= hi / 10:
        return [lo * (hi / lo) ** (k / LOG_TRIALS) for k in range(1, LOG_TRIALS)]
    return [start + f * (bound - start) for bound in (lo, hi) if bound != start for f in SCREEN_STEPS]


def _pinned(base: RobotParams, model: Model) -> bool:
    """The newest effect's value sits at a bound of its range that is not its absent value."""
    cand, values = model.effects[-1], model.values[-1]
    lo, hi = E.bounds(cand.name, base)
    absent = E.absent_values(base, cand.name)
    for v, a, b, off in zip(values, lo, hi, absent):
        # 1 % of the range, or a tenth of a bound that is small against it: a driver's 36 mA limit is 26 mA
        # above the bound 10 mA, under 1 % of the range 10 mA..3 A, and no stand-in
        # (tests/test_diagnosis.py::test_a_value_near_a_small_bound_is_a_measurement_not_a_pin)
        near_a, near_b = min(0.01 * (b - a), 0.1 * abs(a) or math.inf), min(0.01 * (b - a), 0.1 * abs(b) or math.inf)
        if (v - a < near_a and abs(off - a) > near_a) or (b - v < near_b and abs(b - off) > near_b):
            return True
    return False


def _start_values(base: RobotParams, cand: Candidate) -> list[float]:
    """Where a fit starts: the nominal robot's own value for nominal parameters, else absent."""
    effect = E.LIBRARY[cand.name]
    if all(prm.absent is None for prm in effect.params):
        return E.values(base, cand.name, cand.site)
    return E.absent_values(base, cand.name)


def _plainest(tried: list[Model], cands: list[Candidate]) -> Model:
    """The model with the lowest BIC; but among those the data cannot tell from it (BIC within TIE_BIC),
    the one whose newest effect comes first in the candidates' order (the plainer physics), not the one a
    rounding error favours: an S3 offset and S3's ambient leakage are one constant when S3's ambient is."""
    lowest = min(bic(m) for m in tried)
    tied = [m for m in tried if bic(m) - lowest < TIE_BIC]
    return min(tied, key=lambda m: (cands.index(m.effects[-1]), bic(m)))


_OBJECTIVE: Objective | None = None  # what a fitting worker fits: select's, inherited as the worker forks


# The weights travel with each call: select sets them again after the workers forked (still_located).
def _fit_in_worker(base: RobotParams, effects: list[Candidate], start: list[list[float]],
                   sigma: dict[str, float]) -> Model:
    assert _OBJECTIVE is not None
    _OBJECTIVE.sigma = sigma
    return fit_model(_OBJECTIVE, base, effects, start)


def _residuals_in_worker(robots: list[RobotParams], part: str,
                         sigma: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    assert _OBJECTIVE is not None
    _OBJECTIVE.sigma = sigma
    return _OBJECTIVE.residuals_here(robots, part)


def _fitting_pool(obj: Objective, workers: int) -> ProcessPoolExecutor | None:
    """Processes that screen and fit side by side (None for one worker).  Each figure is the one the
    parent would have computed, number for number: only the time changes."""
    global _OBJECTIVE
    if workers <= 1 or "fork" not in multiprocessing.get_all_start_methods():  # Windows: one process
        return None
    _OBJECTIVE = obj  # before the workers fork, so that each has it
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                               initializer=_worker_start)


def _worker_start() -> None:
    """In each worker as it starts: it works alone (its copy of the pool is the parent's), and it leaves
    Ctrl-C to the parent, which stops the workers (_stop_workers); a terminal's Ctrl-C reaches every process
    of its group, and each worker would print its own traceback."""
    assert _OBJECTIVE is not None
    _OBJECTIVE.workers = None
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Interrupted: end the workers' fits now rather than wait for them."""
    terminate = getattr(pool, "terminate_workers", None)  # Python 3.14+
    if terminate is not None:
        terminate()
        return
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        proc.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


Refine = Callable[[Model], tuple[Model, RobotParams]]  # a chosen model -> (it refitted, the base from then on)


def select(obj: Objective, base: RobotParams, cands: list[Candidate],
           progress: Callable[[str], None] | None = None, located: list[str] | None = None,
           workers: int = 1, still_located: Callable[[Model, Objective], list[str]] | None = None,
           refine: Refine | None = None) -> list[Model]:
    """Forward selection, then backward elimination: the chain of accepted models, nominal first.
    workers > 1: each step's screening (by step parts, in shares) and its shortlist's fits run in that many
    processes (forked: where a platform cannot fork, in this one).
    still_located(model, obj): the channels the locator still finds with that twin (report.diagnose); none,
    and no further effect is sought; some, and the next effect's located gain is taken on them.  It may set
    obj.sigma, the weights of the next step (the noise that twin leaves): the twin's costs are then taken
    again under them.  refine(model): each chosen model refitted with what else the base holds (the robot's
    build: calibrate.refit_jointly), and the base the next effects are fitted on."""
    global _OBJECTIVE
    fitters = _fitting_pool(obj, workers)
    obj.workers, obj.worker_count = fitters, workers
    try:
        return _select(obj, base, cands, progress, located, still_located, refine)
    except BaseException:  # Ctrl-C above all: the workers' fits are dropped, not awaited
        if fitters is not None:
            _stop_workers(fitters)
        raise
    finally:
        if fitters is not None:
            fitters.shutdown(wait=True)
        obj.workers, obj.worker_count = None, 1
        _OBJECTIVE = None  # the workers forked with their own copy: hold the recording no longer


def _select(obj: Objective, base: RobotParams, cands: list[Candidate], progress: Callable[[str], None] | None,
            located: list[str] | None, still_located: Callable[[Model, Objective], list[str]] | None = None,
            refine: Refine | None = None) -> list[Model]:
    say = progress or (lambda _t: None)
    now_located = located or []  # what the next effect's located gain is taken on
    r_train, r_test = obj.residuals([base])
    chain = [Model([], [], base, float(r_train[0] @ r_train[0]), float(r_test[0] @ r_test[0]), int(r_train.size),
                   r_test=r_test[0])]
    n_test = int(r_test.size)
    for step in range(MAX_EFFECTS):
        current = chain[-1]
        if current.effects and still_located is not None:
            # The locator, not the held-out cost, decides: a second effect seen in one channel (a sensor
            # turned beside a battery's sag) leaves the cost of all channels within their noise.
            say(f"effect {step + 1}: locating what the fitted twin leaves")
            left = still_located(current, obj)
            if not left:
                break  # the mismatch located is gone: a further effect would fit what the locator calls noise
            if set(left) >= set(now_located):
                # The last effect cleared no channel: the next would be fitted on model error as much as a fault
                # (tests/test_diagnosis.py::test_the_search_stops_when_an_effect_clears_no_channel).
                break
            chain[-1] = current = _costs_again(obj, current)
            # What is left and the fit can weigh; if the fit weighs none of it, what the nominal twin showed.
            now_located = [c for c in left if c in obj.test_columns] or (located or [])
        elif current.effects and current.cost_test < WITHIN_NOISE * n_test:
            break  # no locator: the twin matches the held-out data to within its noise, more would fit the noise
        pool = [c for c in cands if c not in current.effects]
        if not pool:
            break
        say(f"effect {step + 1}: screening {len(pool)} candidates")
        shortlist = screen(obj, base, current, pool, SHORTLIST, now_located)
        fitters = obj.workers
        if fitters is None:
            tried = []
            for cand, start in shortlist:
                say(f"effect {step + 1}: fitting {cand.label()}")
                tried.append(fit_model(obj, base, current.effects + [cand], current.values + [start]))
        else:
            say(f"effect {step + 1}: fitting {', '.join(c.label() for c, _s in shortlist)} side by side")
            tried = list(fitters.map(_fit_in_worker, [base] * len(shortlist),
                                     [current.effects + [c] for c, _s in shortlist],
                                     [current.values + [s] for _c, s in shortlist], [obj.sigma] * len(shortlist)))
        # A value pinned at a fitting bound is a stand-in for something else, not a measurement.
        tried = [m for m in tried if not _pinned(base, m)]
        best = choose(obj, current, tried, cands, now_located)
        if best is None:
            break
        best.rivals = rivals(best, tried)
        best.alternatives = [m.effects[-1].label() for m in best.rivals]
        if refine is not None:
            say(f"effect {step + 1}: fitting {best.effects[-1].label()} and the robot's build together")
            refined, build = refine(best)
            if not _beyond_the_build(obj, build, current, refined, now_located):
                # the build, refitted beside it, explains as much: the effect was the robot as built
                cands = [c for c in cands if c != best.effects[-1]]
                continue
            best, base = refined, build
        chain.append(best)
    return backward(obj, base, chain, say, located or [])


def _beyond_the_build(obj: Objective, base: RobotParams, current: Model, refined: Model, located: list[str]) -> bool:
    """Whether a chosen effect, refitted with the robot's build (select's refine), still earns its place
    against that build with the effects before it: else what it explained was the build (docs/diagnosis.md,
    "The build and the effects together")."""
    without = _apply_all(base, current.effects, current.values)
    r_train, r_test = obj.residuals([without])
    before = Model(current.effects, current.values, without, float(r_train[0] @ r_train[0]),
                   float(r_test[0] @ r_test[0]), int(r_train.size), r_test=r_test[0])
    p = f_test(before.cost_train, refined.cost_train, _sizes(refined.values) - _sizes(current.values),
               refined.n_train, _sizes(refined.values))
    return earns_its_place(obj, before, refined, p, located)[0]


def _costs_again(obj: Objective, model: Model) -> Model:
    """model with its training and held-out costs taken again under obj's weights as they are now."""
    r_train, r_test = obj.residuals([model.params])
    return dataclasses.replace(model, cost_train=float(r_train[0] @ r_train[0]),
                               cost_test=float(r_test[0] @ r_test[0]), r_test=r_test[0])


def _reference(obj: Objective, current: Model, m: Model, refs: dict[tuple[str, ...], Model]) -> Model:
    """What a tried model m is judged against: current, or, where m fitted companions current lacks, current with
    those fitted alone on top of it, so that an effect earns its place beyond what they take up (a pack's
    voltage within its band is the build, not a resistance;
    tests/test_diagnosis.py::test_a_packs_voltage_alone_is_not_credited_to_a_resistance).  refs: those fitted so
    far, by companions."""
    extra = tuple(f for f in m.build if f not in current.build)
    if not extra:
        return current
    if extra not in refs:
        alone = fit_model(obj, current.params, [], [], extra)
        refs[extra] = dataclasses.replace(alone, effects=list(current.effects), values=current.values,
                                          build={**current.build, **alone.build})
    return refs[extra]


def choose(obj: Objective, current: Model, tried: list[Model], cands: list[Candidate],
           located: list[str]) -> Model | None:
    """Of the fitted models that pass the two tests against `current`, the plainest of the lowest BIC (None
    if none passes).  One that fits the training windows a little better and fails held out is no reason
    to stop: the next best may pass
    (tests/test_diagnosis.py::test_the_chosen_effect_is_the_best_of_those_that_pass_held_out).  Sets each
    model's p_value and located_gain, each against _reference's model."""
    passing: list[Model] = []
    refs: dict[tuple[str, ...], Model] = {}
    for m in tried:
        if getattr(obj, "tolerance", None) is not None and obj.tolerance.within(m.effects[-1].name, m.values[-1]):
            continue  # the robot as built, not a fault (tests/test_tolerance.py::test_an_effect_within_tolerance_is_not_named)
        ref = _reference(obj, current, m, refs)
        m.p_value = f_test(ref.cost_train, m.cost_train, _dof(m) - _dof(ref), m.n_train, _dof(m))
        accepted, m.located_gain = earns_its_place(obj, ref, m, m.p_value, located)
        if accepted:
            passing.append(m)
    passing = [m for m in passing if not _constant_in_disguise(obj.rec, m, passing)]
    return _plainest(passing, cands) if passing else None


def leak_swing(rec: Recording, sensor: int, leak: float) -> float:
    """Counts by which a leak of this size varies over the recording: |leak| times the spread (5th to 95th
    percentile) of the sensor's ambient light, a running mean of its readings over AMBIENT_SMOOTH_S."""
    width = max(1, int(round(AMBIENT_SMOOTH_S / rec.sample_period)))
    amb = rec.ir_amb[:, sensor].astype(float)
    if amb.size < width:
        return 0.0
    light = np.convolve(amb, np.ones(width) / width, mode="valid")
    return abs(leak) * float(np.percentile(light, 95) - np.percentile(light, 5))


def _constant_in_disguise(rec: Recording, m: Model, passing: list[Model]) -> bool:
    """True for an ambient leakage that varies by less than a reading's noise over the recording while the
    same sensor's offset passes too, and is not LEAK_STRONG_BIC lower in BIC than it.  Under a steady light
    the two are one constant, and a small edge for the leak comes as easily from the twin's model of the
    room's light as from a leak
    (tests/test_diagnosis.py::test_a_leak_that_varies_less_than_a_readings_noise_is_an_offset)."""
    newest = m.effects[-1]
    if newest.name != "ambient_leakage" or leak_swing(rec, int(newest.site), m.values[-1][0]) >= LEAK_DISTINCT_COUNTS:
        return False
    offset = Candidate("ir_offset", newest.site)
    return any(o.effects[-1] == offset and o.effects[:-1] == m.effects[:-1] and bic(m) > bic(o) - LEAK_STRONG_BIC
               for o in passing)


def earns_its_place(obj: Objective, without: Model, with_it: Model, p_value: float,
                     located: list[str]) -> tuple[bool, float]:
    """(whether an effect stays, its located gain).  It stays if it is significant on the training windows
    (p_value of the F test) and it improves the held-out windows: all their weighted residuals by
    MIN_HELD_OUT_GAIN, or the located channels' own by MIN_LOCATED_GAIN (a track 3 % off shows in the
    turn of each window, a few dozen residuals among thousands that are noise)."""
    gain = 1.0 - with_it.cost_test / without.cost_test if without.cost_test > 0 else 0.0
    located_gain = obj.located_gain(without.r_test, with_it.r_test, located)
    return p_value <= P_MAX and (gain >= MIN_HELD_OUT_GAIN or located_gain >= MIN_LOCATED_GAIN), located_gain


def _sizes(values: list[list[float]]) -> int:
    return sum(len(v) for v in values)


def _dof(model: Model) -> int:
    """The values a model fitted: its effects' and their companions'."""
    return _sizes(model.values) + len(model.build)


def backward(obj: Objective, base: RobotParams, chain: list[Model],
             say: Callable[[str], None] = lambda _t: None, located: list[str] | None = None) -> list[Model]:
    """Backward elimination after the forward pass: an effect chosen early may be made redundant by one
    chosen later (a stand-in taken first because its one-step screening promised more), and is dropped
    if the others without it, refitted, are as good (F test or held-out gain, as for adding one).  The
    chain is then rebuilt, each step refitted, so every effect keeps its evidence."""
    final = chain[-1]
    for i in range(len(final.effects) - 1):  # the last one was just judged against all the others
        rest = [j for j in range(len(final.effects)) if j != i]
        effects, values = [final.effects[j] for j in rest], [final.values[j] for j in rest]
        say(f"checking that {final.effects[i].label()} is still needed")
        reduced = fit_model(obj, base, effects, values, tuple(final.build))
        p = f_test(reduced.cost_train, final.cost_train, _dof(final) - _dof(reduced), final.n_train, _dof(final))
        if earns_its_place(obj, reduced, final, p, located or [])[0]:
            continue
        rebuilt = chain[:1]
        for n in range(1, len(effects) + 1):
            m = reduced if n == len(effects) else fit_model(obj, base, effects[:n], values[:n])
            m.p_value = f_test(rebuilt[-1].cost_train, m.cost_train, len(values[n - 1]), m.n_train, _sizes(values[:n]))
            m.alternatives = chain[rest[n - 1] + 1].alternatives
            m.rivals = chain[rest[n - 1] + 1].rivals
            rebuilt.append(m)
        for prev, m in zip(rebuilt, rebuilt[1:]):  # each step's located gain, for its evidence
            m.located_gain = earns_its_place(obj, prev, m, m.p_value, located or [])[1]
        return backward(obj, base, rebuilt, say, located)
    return chain
