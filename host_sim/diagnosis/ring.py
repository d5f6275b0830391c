"""The IR ring's own law: the factor by which every pair reads above or below the twin's law.

A robot's sensors follow their own curve and its walls reflect as they do, so all its pairs may read some per cent
above or below the datasheet's law at once; a pair's gain band is its efficiency against the other pairs. What the
pairs share is then the law's, not a fault of any one pair: each pair's gain is fitted on its own readings (linear
least squares), and their median over the pairs that faced a wall for MIN_REGIME_S scales the law (ir_gain) before
anything is compared.  The median holds while fewer than half its pairs are faulty: MIN_PAIRS of 3 hold one.
docs/diagnosis.md, "The ring's own law"; tests/test_ring.py.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from host_sim.diagnosis.channels import SENSOR_NAMES, ring_comparable
from host_sim.diagnosis.compare import ir_unjudged
from host_sim.diagnosis.locate import MIN_REGIME_S, near_wall_seconds, regimes
from host_sim.diagnosis.windows import Windows, make_windows, sensors_on_track
from host_sim.physics.params import RobotParams
from host_sim.physics.world import World
from host_sim.recordings.recording import Recording

MIN_PAIRS = 3  # pairs judged: the median of 3 holds with one of them faulty


@dataclass(frozen=True)
class RingLaw:
    params: RobotParams  # the datasheet's robot with its law scaled by factor
    factor: float
    gains: tuple[float, ...]  # each pair's gain against the twin's law (nan where its readings hold no reflection)
    pairs: tuple[int, ...]  # those the median is over: the pairs that faced a wall long enough

    def words(self) -> str:
        names = ", ".join(SENSOR_NAMES[k] for k in self.pairs)
        return (f"the IR ring reads {100 * (self.factor - 1):+.1f} % against the twin's law (the median over {names}, "
                f"which faced a wall for {MIN_REGIME_S:.0f} s or more): the walls' reflectance or the sensors' own "
                f"curve, so the law is scaled by it and each pair is judged against the others")


def pair_gains(rec: Recording, windows: Windows, p: RobotParams, world: World) -> np.ndarray:
    """(S,) each pair's gain against p's law: the least-squares factor of the twin's reflected light that best
    gives the recorded one, over the readings judged and below the ADC's ceiling (nan where there is none)."""
    rows = windows.index[:, 1:]  # the readings the IR channels judge (channels.build_channels)
    unjudged, _far = ir_unjudged(rec, windows, p, world)
    on, amb = sensors_on_track(rec, rows, [p, p.replace(ir_gain=0.5 * p.ir_gain)], world)
    refl = on - amb
    per_gain = 2.0 * (refl[0] - refl[1])  # the reflected light in proportion to the gain
    y = (rec.ir_on - rec.ir_amb)[rows].astype(float) - (refl[0] - per_gain)
    keep = (on[0] < p.adc_max) & (rec.ir_on[rows] < p.adc_max)
    if unjudged is not None:
        keep &= ~unjudged
    den = (np.where(keep, per_gain, 0.0) ** 2).sum(axis=(0, 1))
    num = np.where(keep, per_gain * y, 0.0).sum(axis=(0, 1))
    return np.divide(num, den, out=np.full(den.shape, np.nan), where=den > 0)


def ring_law(rec: Recording, datasheet: RobotParams, world: World | None, seconds: float) -> RingLaw | None:
    """The ring's law on rec (its `seconds` windows), or None where fewer than MIN_PAIRS pairs faced a wall for
    MIN_REGIME_S, or the ring is not judged at all (no pose, no wall, or readings that are not the twin's ring's:
    channels.ring_comparable)."""
    if rec.pose is None or world is None or not world.n_walls or not ring_comparable(rec, datasheet):
        return None
    windows = make_windows(rec, seconds)
    near = near_wall_seconds(rec, regimes(rec, windows, datasheet, world))
    gains = pair_gains(rec, windows, datasheet, world)
    pairs = tuple(k for k in range(rec.n_ir) if near[k] >= MIN_REGIME_S and gains[k] > 0)
    if len(pairs) < MIN_PAIRS:
        return None
    factor = float(np.median(gains[list(pairs)]))
    return RingLaw(datasheet.replace(ir_gain=datasheet.ir_gain * factor), factor,
                   tuple(float(g) for g in gains), pairs)
