"""The baseline beside diagnosis: SINDy with control (PySINDy) on the nominal twin's residual.

Each wheel's per-period residual (recorded - twin, rad/s) on diagnosis's training windows, as a sparse sum of
polynomial terms (degree <= 2) in the twin's wheel speeds and the recorded current references, plus tanh of
each speed; judged on the same held-out windows.  docs/proving-ground.md, "The SINDy baseline".
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from host_sim.diagnosis.channels import fit_percent
from host_sim.diagnosis.compare import compare
from host_sim.physics.params import RobotParams
from host_sim.recordings.recording import Recording
from host_sim.physics.world import World

FEATURES = ["w_l", "w_r", "i_l", "i_r"]
THRESHOLDS = (0.003, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5)
TANH_GAIN = 3.0  # tanh(3 z) of a unit-RMS feature: a sign that is smooth over a third of the typical size
VALIDATION_SLACK = 0.02
RIDGE = 0.01


def _library() -> Any:
    import pysindy as ps  # type: ignore[import-untyped]

    tanh = ps.CustomLibrary(library_functions=[lambda z: np.tanh(TANH_GAIN * z)],
                            function_names=[lambda s: f"tanh({s})"])
    # tanh of the wheel speeds only: a sign of a current is no physics, and nearly collinear with it.
    return ps.GeneralizedLibrary([ps.PolynomialLibrary(degree=2), tanh], inputs_per_library=[[0, 1, 2, 3], [0, 1]])


def _fit(z: np.ndarray, u: np.ndarray, r: np.ndarray, threshold: float, dt: float) -> Any:
    import pysindy as ps

    # A light ridge (RIDGE per row): a firmware's few discrete current levels make i, i^2 and 1 collinear.
    optimizer = ps.STLSQ(threshold=threshold, alpha=RIDGE * len(z))
    model = ps.SINDy(feature_library=_library(), optimizer=optimizer)
    model.fit(z, t=dt, x_dot=r, u=u, feature_names=FEATURES)
    return model


def _choose_threshold(z: np.ndarray, u: np.ndarray, r: np.ndarray, train_rows: np.ndarray, dt: float) -> float:
    """The sparsest threshold whose validation error (every 4th training window) is within 2 % of the best."""
    windows = np.nonzero(train_rows)[0]
    valid = np.zeros_like(train_rows)
    valid[windows[3::4]] = True
    fit_on = train_rows & ~valid
    errors = []
    for th in THRESHOLDS:
        model = _fit(z[fit_on].reshape(-1, 2), u[fit_on].reshape(-1, 2), r[fit_on].reshape(-1, 2), th, dt)
        pred = np.asarray(model.predict(z[valid].reshape(-1, 2), u=u[valid].reshape(-1, 2)))
        errors.append(float(np.sum((r[valid].reshape(-1, 2) - pred) ** 2)))
    best = min(errors)
    return max(th for th, e in zip(THRESHOLDS, errors) if e <= best * (1 + VALIDATION_SLACK))


def sindy_case(rec: Recording, params: RobotParams, world: World | None, seconds: float = 1.0) -> dict[str, Any]:
    """SINDy on the nominal twin's wheel residuals: held-out fit before/after, threshold, active terms."""
    t0 = time.perf_counter()
    cmp = compare(rec, params, world, seconds, locate=False)
    chans = [cmp.channel("wheel_l"), cmp.channel("wheel_r")]
    dt = rec.sample_period
    ticks = np.array([params.ticks_per_rev + params.ticks_per_rev_delta_l,
                      params.ticks_per_rev + params.ticks_per_rev_delta_r])
    to_rad_s = 2 * np.pi / ticks / dt  # ticks per period -> rad/s
    y = np.stack([c.y for c in chans], axis=-1)  # (W, T-1, 2) recorded ticks per period
    y_hat = np.stack([c.y_hat[:, 0] for c in chans], axis=-1)  # the nominal twin's
    u = rec.cmd[cmp.windows.index[:, :-1]].astype(float)
    w = y_hat * to_rad_s
    r = (y - y_hat) * to_rad_s
    train = ~cmp.windows.held_out & ~cmp.contact
    test = cmp.windows.held_out & ~cmp.contact
    # Unit RMS on the training windows (features and target), so one threshold means the same everywhere.
    sw, su, sr = (np.sqrt(np.mean(a[train] ** 2, axis=(0, 1))) + 1e-12 for a in (w, u, r))
    z, uz, rz = w / sw, u / su, r / sr
    threshold = _choose_threshold(z, uz, rz, train, dt)
    model = _fit(z[train].reshape(-1, 2), uz[train].reshape(-1, 2), rz[train].reshape(-1, 2), threshold, dt)
    pred = np.asarray(model.predict(z[test].reshape(-1, 2), u=uz[test].reshape(-1, 2))).reshape(y[test].shape)
    pred = pred * sr / to_rad_s
    corrected = y_hat[test] + pred
    names = model.get_feature_names()
    coefs = np.asarray(model.coefficients())
    terms = [{"equation": FEATURES[e], "term": names[j], "coef": float(coefs[e, j])}
             for e in range(2) for j in range(len(names)) if coefs[e, j] != 0.0]
    return {"fit_before": {c.name: fit_percent(y[test][..., k], y_hat[test][..., k]) for k, c in enumerate(chans)},
            "fit_after": {c.name: fit_percent(y[test][..., k], corrected[..., k]) for k, c in enumerate(chans)},
            "threshold": threshold, "terms": terms, "n_active": len(terms), "n_library": 2 * len(names),
            "train_windows": int(train.sum()), "test_windows": int(test.sum()),
            "seconds": time.perf_counter() - t0}
