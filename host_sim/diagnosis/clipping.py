"""IR readings held at a ceiling below the ADC's full scale: clipped (an ADC reference set low, an amplifier's
rail), which the twin does not hold.  Found from the readings alone and never fitted: the clipped readings
are not judged, and each clip is reported as located and unexplained (docs/diagnosis.md, "Clipped readings").

A noisy reading that is not clipped spreads over its noise about any level it holds, so its highest value is
rarer than the values just below it.  A clip gathers every reading beyond it onto one value: many readings
at the top, more than in the noise band under it, of a signal that also reads well under it (a sensor that
reads one value throughout is dead or absent, not clipped).  Without noise (a datasheet's ir_noise under
half a count) a steady reading looks the same, so there the top must be reached in more than one visit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from host_sim.physics.params import RobotParams
from host_sim.recordings.recording import Recording

CLIP_MIN_ROWS = 5  # readings at the top: fewer, and a noisy signal's highest value may repeat by chance
CLIP_MIN_VISITS = 2  # separate runs of them, where the readings have no noise: one is a steady reading
NOISE_BAND = 2.0  # the band under the top, in noise levels, whose readings a clip must outnumber


@dataclass(frozen=True)
class Clip:
    """Sensor `sensor`'s emitter-on readings stop at `level` counts; `rows` (n,) bool: the readings there."""

    sensor: int
    level: int
    rows: np.ndarray


def clipped(rec: Recording, p: RobotParams) -> list[Clip]:
    """The sensors whose emitter-on readings pile up at a value under the ADC's full scale
    (tests/test_clipping.py::test_readings_piled_below_full_scale_are_a_clip_noisy_or_full_scale_ones_are_not)."""
    out = []
    band = max(2, math.ceil(NOISE_BAND * p.ir_noise))
    for k in range(rec.n_ir):
        v = np.asarray(rec.ir_on[:, k])
        if not v.size:
            continue
        top = int(v.max())
        if top >= p.adc_max:  # the ADC's own full scale: the twin's saturation
            continue
        at = v == top
        under = int(((v >= top - band) & (v < top)).sum())
        below = int((v < top - band).sum())  # the signal away from the ceiling
        visits = int(at[0]) + int((np.diff(at.astype(np.int8)) == 1).sum())
        steady = p.ir_noise < 0.5 and visits < CLIP_MIN_VISITS
        if int(at.sum()) >= CLIP_MIN_ROWS and int(at.sum()) > under and below >= CLIP_MIN_ROWS and not steady:
            out.append(Clip(k, top, at))
    return out


def unjudged_clips(clips: list[Clip], rows: np.ndarray, n_ir: int) -> np.ndarray:
    """(*rows.shape, n_ir) bool: the readings of `rows` (indices into the recording) that a clip holds."""
    mask = np.zeros((*rows.shape, n_ir), dtype=bool)
    for c in clips:
        if c.sensor < n_ir:
            mask[..., c.sensor] = c.rows[rows]
    return mask

