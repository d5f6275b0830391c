"""Calibrate the twin within the datasheet's tolerance: the robot's own build, fitted before any effect.

Each wheel's radius, torque constant, friction and breakaway friction, the track, the caster's rolling drag,
the axles' Stribeck speed, the battery's voltage and each located sensor's gain are fitted as nuisance
parameters, bounded by their bands (tolerance.py) with a Gaussian prior of half a band, on the training
windows alone; the radii and the track where the odometry measured them are held at its values (held).
Reference: docs/diagnosis.md, "Within the datasheet's tolerance".
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy import optimize

from host_sim.diagnosis.channels import drive_located, located_sensors
from host_sim.diagnosis.fit import (FIT_FTOL, FIT_XTOL, Model, Objective, sandwich_intervals, earns_its_place,
                                   f_test, touching_runs)
from host_sim.diagnosis.odometry import Odometry
from host_sim.physics import effects as E
from host_sim.diagnosis.tolerance import ABSOLUTE, UNIT_OF, Tolerance, relative_bounds
from host_sim.physics.params import RobotParams

PRIOR_SD = 0.5  # of a band: a band holds about 95 % of robots built to the datasheet (±2 sd)
MAX_EVALUATIONS = 20  # of the least-squares fit; each runs every training window for each parameter
AT_EDGE = 0.98  # of a band: a value fitted this far out sits at the tolerance's edge (said so in the report)
START_INSIDE = 0.1  # of a band: where a one-sided nuisance's fit starts (inside)
RELEASE = 5.0  # bands: how far an edge's nuisance may go when freed to ask whether it holds back a fault
PER_WHEEL = ("wheel_radius", "torque_constant", "coulomb_friction", "viscous_friction", "stiction")
WHEEL_FIELD = {"wheel_radius": "wheel_radius_delta_{w}", "torque_constant": "torque_constant_delta_{w}",
               "coulomb_friction": "coulomb_friction_delta_{w}", "viscous_friction": "viscous_friction_delta_{w}",
               "armature_resistance": "armature_resistance_delta_{w}", "stiction": "stiction_{w}"}


@dataclass(frozen=True)
class Nuisance:
    """One value of the robot's build: the datasheet quantity its band is of, and the field it sets."""

    quantity: str  # a key of the tolerance's bands
    field: str  # the RobotParams field set
    index: int | None = None  # an entry of a per-pair field (ir_gain_scale)
    where: str = ""  # "left", "right", "sensor 3", or "" for the robot's

    def label(self) -> str:
        return f"{self.quantity} ({self.where})" if self.where else self.quantity


@dataclass
class Calibration:
    """The twin calibrated within tolerance: its parameters, and each nuisance's relative value."""

    params: RobotParams
    nuisances: list[Nuisance] = field(default_factory=list)
    values: list[float] = field(default_factory=list)  # relative to the datasheet, e.g. -0.004
    bands: list[float] = field(default_factory=list)
    held: tuple[Nuisance, ...] = ()  # measured apart, by the odometry: no fit of the dynamics moves them

    def to_json(self) -> list[dict[str, Any]]:
        return [{"value": n.quantity, "where": n.where, "relative": round(v, 5), "band": b,
                 "at_edge": _at_edge(n, v, b), "from": "odometry" if n in self.held else "fit"}
                for n, v, b in zip(self.nuisances, self.values, self.bands)]

    def at_edge(self) -> list[Nuisance]:
        """The nuisances fitted at their band's edge: the data would take them beyond the tolerance."""
        return [n for n, v, b in zip(self.nuisances, self.values, self.bands) if _at_edge(n, v, b)]

    def at_datasheet(self, tol: Tolerance, which: set[Nuisance] | None = None) -> Calibration:
        """The same nuisances, those of `which` (all by default) at the datasheet's values (relative 0):
        where a search starts for a group whose calibration took up part of a fault
        (report._within_tolerance)."""
        values = [0.0 if (which is None or n in which) and n not in self.held else v
                  for n, v in zip(self.nuisances, self.values)]
        return Calibration(set_values(tol.datasheet, tol, self.nuisances, np.array(values)), list(self.nuisances),
                           values, list(self.bands), self.held)

    def words(self) -> str:
        moved = [(n, v) for n, v in zip(self.nuisances, self.values) if abs(v) >= 5e-4]
        return ", ".join((f"{n.label()} {v:+.3g} {UNIT_OF[n.quantity]}" if n.quantity in UNIT_OF
                          else f"{n.label()} {100 * v:+.1f} %") + (" (odometry)" if n in self.held else "")
                         for n, v in moved) or "no value moved"


def drive_nuisances(tol: Tolerance, has_vbat: bool, bench: bool) -> list[Nuisance]:
    """The drive's: each wheel's radius (not on a bench: no floor), torque constant and friction, each
    motor's resistance on a bridge drive, the track and the caster's rolling drag (not on a bench), the axles'
    Stribeck speed, and the battery where it is recorded.  A caster always rolls with some drag, which the
    datasheet gives as none (tests/test_tolerance.py::test_a_caster_that_rolls_with_some_drag_is_the_build_not_a_fault)."""
    quantities = [q for q in PER_WHEEL if not (bench and q == "wheel_radius")]
    if tol.datasheet.drive_kind != "current":
        quantities.append("armature_resistance")
    out = [Nuisance(q, WHEEL_FIELD[q].format(w=w[0]), where=w) for q in quantities for w in ("left", "right")]
    out += [] if bench else [Nuisance("half_axle", "half_axle"), Nuisance("caster_drag", "caster_drag")]
    out += [Nuisance("stribeck_speed", "stribeck_speed")]
    out += [Nuisance("battery_voltage", "battery_voltage")] if has_vbat else []
    return [n for n in out if tol.bands.get(n.quantity, 0.0) > 0]


def sensor_nuisances(tol: Tolerance, sensors: list[int]) -> list[Nuisance]:
    """Each located sensor's optical gain."""
    if tol.bands.get("ir_gain", 0.0) <= 0:
        return []
    return [Nuisance("ir_gain", "ir_gain_scale", k, f"sensor {k}") for k in sensors]


def held_by_odometry(odo: Odometry | None, nuisances: list[Nuisance], tol: Tolerance) -> dict[Nuisance, float]:
    """The kinematic nuisances the odometry measured (each wheel's radius, the track: encoders against the
    tracker, no dynamics) within their bands, each at its value.  A fit of the dynamics moves them to take up
    the twin's own model error, and the turn and the travel it leaves are then located; one the odometry puts
    at or beyond its band's edge is no build but a fault's sign, and is fitted as the rest
    (tests/test_tolerance.py::test_the_radii_and_the_track_are_the_odometrys_not_the_dynamics)."""
    if odo is None:
        return {}
    value = {("wheel_radius", "left"): odo.per_count[0], ("wheel_radius", "right"): odo.per_count[1],
             ("half_axle", ""): odo.half_axle}
    return {n: float(value[(n.quantity, n.where)]) for n in nuisances if (n.quantity, n.where) in value
            and not _at_edge(n, value[(n.quantity, n.where)], tol.bands[n.quantity])}


def set_values(p: RobotParams, tol: Tolerance, nuisances: list[Nuisance], x: np.ndarray) -> RobotParams:
    """p with each nuisance at its relative value x (about the datasheet; a wheel's delta field carries it)."""
    changes: dict[str, Any] = {}
    ds = tol.datasheet
    for n, v in zip(nuisances, x):
        if n.quantity in ABSOLUTE:  # absent on the datasheet: the value itself
            changes[n.field] = float(v)
        elif n.index is not None:
            scales = list(changes.get(n.field, getattr(p, n.field)))
            scales[n.index] = float(getattr(ds, n.field)[n.index]) * (1.0 + float(v))
            changes[n.field] = tuple(scales)
        elif n.field != n.quantity:  # a wheel's delta from the datasheet value
            changes[n.field] = float(getattr(ds, n.field)) + float(getattr(ds, n.quantity)) * float(v)
        else:
            changes[n.field] = float(getattr(ds, n.field)) * (1.0 + float(v))
    return dataclasses.replace(p, **changes)


def bounds(nuisances: list[Nuisance], band: np.ndarray, reach: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Each nuisance's (lower, upper) relative bound, `reach` bands out (tolerance.relative_bounds)."""
    return relative_bounds([n.quantity for n in nuisances], band, reach)


def _at_edge(n: Nuisance, v: float, band: float) -> bool:
    """The nuisance's value v sits within AT_EDGE of its upper bound, or of a lower one below the datasheet."""
    (lo,), (hi,) = bounds([n], np.array([band]))
    # a JSON bool, not numpy's (tests/test_diagnosis.py::test_json_html_and_parameter_file_from_the_command)
    return bool(v >= AT_EDGE * hi or (lo < 0.0 and v <= AT_EDGE * lo))


def inside(x0: np.ndarray, lo: np.ndarray, band: np.ndarray) -> np.ndarray:
    """x0 with each one-sided nuisance (lower bound 0) at least START_INSIDE of its band from it: started on
    its bound, the fit's first trust-region step was rejected and it ended where it began
    (tests/test_tolerance.py::test_a_robot_within_its_tolerance_is_a_match)."""
    return np.where(lo == 0.0, np.maximum(x0, START_INSIDE * band), x0)


def calibrate(obj: Objective, params: RobotParams, tol: Tolerance, nuisances: list[Nuisance],
              start: list[float] | None = None, held: dict[Nuisance, float] | None = None) -> Calibration:
    """The MAP fit of the nuisances on obj's training windows: weighted residuals and the prior's rows
    x / (PRIOR_SD band), x within its bounds (bounds), from start (default the datasheet,
    x = 0; inside), those of held at its values.  Nothing held out is seen."""
    if not nuisances:
        return Calibration(params)
    held = held or {}
    band = np.array([tol.bands[n.quantity] for n in nuisances])
    lo, hi = bounds(nuisances, band)
    x0 = np.zeros(len(nuisances)) if start is None else np.array(start, dtype=float)
    x0 = np.array([held.get(n, v) for n, v in zip(nuisances, x0)])
    free = np.array([n not in held for n in nuisances])
    x = _fit_free(obj, lambda x: set_values(params, tol, nuisances, x), inside(x0, lo, band), lo, hi,
                  PRIOR_SD * band, free)
    return Calibration(set_values(params, tol, nuisances, x), list(nuisances), [float(v) for v in x],
                       [float(b) for b in band], tuple(n for n in nuisances if n in held))


def _fit_free(obj: Objective, robot: Callable[[np.ndarray], RobotParams], x0: np.ndarray, lo: np.ndarray,
              hi: np.ndarray, sd: np.ndarray, free: np.ndarray) -> np.ndarray:
    """_least_squares over the entries free marks, the others held at x0's: the whole x fitted."""
    if not free.any():
        return x0

    def whole(x: np.ndarray) -> np.ndarray:
        out = x0.copy()
        out[free] = x
        return out

    return whole(_least_squares(obj, lambda x: robot(whole(x)), x0[free], lo[free], hi[free], sd[free])[0])


def refit_jointly(obj: Objective, tol: Tolerance, cal: Calibration, model: Model) -> tuple[Model, Calibration]:
    """model's effects and the calibration's nuisances fitted together (the nuisances with their prior), from
    where each stands: an effect fitted on a twin whose build took up part of its mismatch is biased, and
    jointly the build returns towards the datasheet where the effect explains it
    (tests/test_tolerance.py::test_the_build_and_the_effect_are_fitted_together).  A nuisance whose field an
    effect sets is left to the effect; only nuisances of the channels obj weighs are fitted."""
    taken = {target for c in model.effects for target in E.targets(c.name, c.site)}
    weighed, drive = set(located_sensors(obj.names)), drive_located(obj.names)
    keep = [i for i, n in enumerate(cal.nuisances) if (n.field, n.index) not in taken and n not in cal.held
            and ((n.index is None and drive) or (n.index is not None and n.index in weighed))]
    if not keep or not model.effects:
        return model, cal
    nuis = [cal.nuisances[i] for i in keep]
    band = np.array([cal.bands[i] for i in keep])
    sizes = [len(v) for v in model.values]
    lo_e, hi_e = (np.concatenate([E.bounds(c.name, tol.datasheet)[j] for c in model.effects]) for j in (0, 1))
    lo_n, hi_n = bounds(nuis, band)
    lo, hi = np.concatenate([lo_n, lo_e]), np.concatenate([hi_n, hi_e])
    x0 = np.clip(np.concatenate([inside(np.array([cal.values[i] for i in keep]), lo[:len(keep)], band),
                                 np.concatenate(model.values)]), lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo))
    sd = np.concatenate([PRIOR_SD * band, np.full(len(lo_e), np.inf)])
    base = set_values(tol.datasheet, tol, [n for n in cal.nuisances if n not in nuis],
                      np.array([v for n, v in zip(cal.nuisances, cal.values) if n not in nuis]))

    def robot(x: np.ndarray) -> RobotParams:
        values, at = [], len(nuis)
        for size in sizes:
            values.append([float(v) for v in x[at:at + size]])
            at += size
        p = set_values(base, tol, nuis, x[:len(nuis)])
        for cand, v in zip(model.effects, values):
            p = E.apply(p, cand.name, cand.site, v)
        return p

    x, jac, r_train = _least_squares(obj, robot, x0, lo, hi, sd)
    train, test = obj.residuals([robot(x)])
    n = train.shape[1]  # the data's rows; the prior's follow
    info = np.diag(np.where(np.isfinite(sd), 1.0 / sd, 0.0) ** 2)
    ci = sandwich_intervals(x, jac[:n], r_train[:n], [1] * len(nuis) + sizes, lo, hi,
                             touching_runs(obj.windows, obj.train_windows), info)[len(nuis):]
    values = [[float(v) for v in x[len(nuis) + sum(sizes[:k]):len(nuis) + sum(sizes[:k + 1])]]
              for k in range(len(sizes))]
    joint = dataclasses.replace(model, values=values, params=robot(x), cost_train=float(train[0] @ train[0]),
                                cost_test=float(test[0] @ test[0]), r_test=test[0], ci95=ci)
    values_now = [float(x[nuis.index(n)]) if n in nuis else v for n, v in zip(cal.nuisances, cal.values)]
    build = Calibration(set_values(tol.datasheet, tol, cal.nuisances, np.array(values_now)), list(cal.nuisances),
                        values_now, list(cal.bands), cal.held)
    return joint, build


def _least_squares(obj: Objective, robot: Callable[[np.ndarray], RobotParams], x0: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray, sd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounded least squares of obj's training residuals and the prior's rows (x - 0) / sd (none where sd is
    infinite), the Jacobian by one batch of nudged twins: (x, the Jacobian with the prior's rows, the
    residuals with them)."""
    step = 1e-3 * (hi - lo)
    prior = np.isfinite(sd)
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = x.tobytes()
        if key not in cache:
            h = np.where(x + step <= hi, step, -step)
            points = [x] + [x + np.eye(len(x))[i] * h[i] for i in range(len(x))]
            train = obj.residuals([robot(pt) for pt in points], part="train")[0]
            jac = np.vstack([((train[1:] - train[0]) / h[:, None]).T, np.diag(1.0 / sd[prior]) @ np.eye(len(x))[prior]])
            cache.clear()
            cache[key] = (np.concatenate([train[0], x[prior] / sd[prior]]), jac)
        return cache[key]

    sol = optimize.least_squares(lambda x: evaluate(x)[0], x0, jac=lambda x: evaluate(x)[1], bounds=(lo, hi),
                                 x_scale=hi - lo, max_nfev=MAX_EVALUATIONS, ftol=FIT_FTOL, xtol=FIT_XTOL)
    x = np.clip(sol.x, lo, hi)
    r, jac = evaluate(x)
    return x, jac, r


def edge_binds(obj: Objective, params: RobotParams, tol: Tolerance, cal: Calibration, located: list[str]) -> bool:
    """Whether the nuisances at their band's edge hold back a fault: fitted again with those freed (RELEASE
    bands, no prior), the twin must earn it as an effect must (fit's F test and held-out gain on obj's
    held-out windows, against the calibration).  Else the edge is the twin's own model pressing on it,
    not the robot (tests/test_tolerance.py::test_a_fault_the_build_can_almost_take_up_is_still_named)."""
    edge = [i for i, (n, v, b) in enumerate(zip(cal.nuisances, cal.values, cal.bands)) if _at_edge(n, v, b)]
    if not edge:
        return False
    band = np.array(cal.bands)
    (lo, hi), sd = bounds(cal.nuisances, band), PRIOR_SD * band
    released = bounds(cal.nuisances, band, RELEASE)
    lo[edge], hi[edge], sd[edge] = released[0][edge], released[1][edge], np.inf
    free = np.array([n not in cal.held for n in cal.nuisances])  # held ones lie within their bands
    freed = _fit_free(obj, lambda x: set_values(params, tol, cal.nuisances, x),
                      inside(np.array(cal.values), lo, band), lo, hi, sd, free)
    robots = [set_values(params, tol, cal.nuisances, np.array(cal.values)),
              set_values(params, tol, cal.nuisances, freed)]
    train, test = obj.residuals(robots)
    held = Model([], [], robots[0], float(train[0] @ train[0]), float(test[0] @ test[0]), int(train[0].size),
                 r_test=test[0])
    free = Model([], [], robots[1], float(train[1] @ train[1]), float(test[1] @ test[1]), int(train[1].size),
                 r_test=test[1])
    p = f_test(held.cost_train, free.cost_train, len(edge), free.n_train, len(cal.values))
    return earns_its_place(obj, held, free, p, located)[0]
