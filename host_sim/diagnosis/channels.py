"""Residual channels: what the recording and the twin are compared on, period by period within each window.

Per period: each wheel's counts, the body's motion, each IR sensor's reflected and ambient light, the
battery; per window: the pose at its end and the totals (travel, turn, counts).  The channel table and
the fit %: docs/diagnosis.md, "Channels".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from host_sim.diagnosis.windows import WindowRun, Windows, sensors_on_track
from host_sim.physics.params import MAX_IR_PAIRS, RobotParams
from host_sim.recordings.recording import Recording
from host_sim.physics.world import World
from host_sim.sensors import ir_sensor

# The firmware's ring by name; the pairs of a larger ring (ir_bearings) by number.
SENSOR_NAMES = ("S1 front", "S2 front-left", "S3 left", "S4 back-left", "S5 back", "S6 back-right",
                "S7 right", "S8 front-right") + tuple(f"S{k + 1}" for k in range(8, MAX_IR_PAIRS))
WHEELS = ("wheel_l", "wheel_r")
MOTION = ("forward", "lateral", "heading_rate")
IR = tuple(f"ir_{k}" for k in range(MAX_IR_PAIRS))
AMBIENT = tuple(f"amb_{k}" for k in range(MAX_IR_PAIRS))
# Each window's totals (locate.locate_scale), where an odometry-sized error shows: channel -> its total.
# The IR law is the datasheet's typical curve, known at its calibration points to about the spread of one
# batch's pairs: a reading that departs from it by less, in a regime, is a part's own curve, not a fault
# (docs/diagnosis.md, "Within the datasheet's tolerance"; tests/test_tolerance.py::
# test_an_ir_curve_within_its_tolerance_is_not_located).
IR_RESPONSE_TOLERANCE = 0.15
# Beyond the datasheet's farthest calibration point the law is C/x^2 extrapolated; how a pair's response
# fades there, as its spot outgrows the wall and its cones part, is its optics', which the datasheet does not
# give: the twin's reading there is known only to its own size
# (tests/test_tolerance.py::test_an_ir_reading_beyond_the_calibrated_range_is_known_to_its_own_size).
IR_EXTRAPOLATED_TOLERANCE = 1.0
# A lamp's light at a receiver is the world file's lamp seen through the receiver's angular response, which
# a datasheet's polar plot gives only loosely: off its axis a Lambertian and a narrower receiver differ by a
# factor of two.  An ambient reading within the twin's lamp light of the twin's is the room as modelled, not
# the robot (tests/test_tolerance.py::test_ambient_light_within_the_lamps_own_size_is_the_room).
LAMP_RESPONSE_TOLERANCE = 1.0
ACCUMULATED = {"forward": "travel", "heading_rate": "turn", "wheel_l": "count_l", "wheel_r": "count_r"}


def drive_channel(name: str) -> bool:
    """A channel of the drive (the wheels, the body's motion, their totals, the battery), not of a sensor."""
    return name in WHEELS or name in MOTION or name in ACCUMULATED.values() or name == "vbat"


def sensor_channel(name: str) -> bool:
    """An IR or ambient channel: the twin's sensors on the recorded track, whatever the twin's motion."""
    return name.startswith(("ir_", "amb_"))


def located_sensors(channels: list[str]) -> list[int]:
    """The IR pairs these channels point to, in order."""
    return sorted({int(c.split("_")[1]) for c in channels if sensor_channel(c)})


def drive_located(channels: list[str]) -> bool:
    """Whether any of these channels is the drive's."""
    return any(drive_channel(c) for c in channels)


def judged_windows(name: str, contact: np.ndarray) -> np.ndarray:
    """(W,) bool: the windows a channel is judged on.  A wall contact the twin's dynamics get wrong is left
    out of the drive's channels; the sensors' readings come from the recorded track, so their windows at a
    wall are judged too (a robot pressed against one shows its IR pairs a wall the whole time)."""
    return np.ones_like(contact) if sensor_channel(name) else ~contact


@dataclass
class Channel:
    """One compared quantity: recorded y and the twin's y_hat, per window and period."""

    name: str
    unit: str
    y: np.ndarray  # (W, T - 1) recorded
    y_hat: np.ndarray  # (W, N, T - 1) the twin, one row per parameter set
    noise_floor: float  # the residual's standard deviation when the twin is right (quantisation, sensor noise)
    locate: bool = True  # residuals per period (True) or accumulated along the window (pose)
    relative: bool = True  # a mismatch must also be large against the signal (not for a level: vbat)
    tolerance: float = 0.0  # a bias within this share of the signal is the model's own tolerance (locate)
    # (W, T - 1) the signal a bias is held against where not y: the lamps' light (ambient), the twin's (far IR)
    scale: np.ndarray | None = None

    def residual(self, s: int = 0) -> np.ndarray:
        """(W, T - 1) recorded minus the twin with parameter set s."""
        return self.y - self.y_hat[:, s]


def _motion(pose: np.ndarray) -> np.ndarray:
    """(..., T, 3) poses -> (..., T - 1, 3): forward, lateral, heading change per period, in the start frame."""
    d = np.diff(pose, axis=-2)
    phi = pose[..., :-1, 2]
    c, s = np.cos(phi), np.sin(phi)
    out = np.empty(d.shape)
    out[..., 0] = c * d[..., 0] + s * d[..., 1]
    out[..., 1] = -s * d[..., 0] + c * d[..., 1]
    out[..., 2] = (d[..., 2] + np.pi) % (2 * np.pi) - np.pi
    return out


def build_channels(rec: Recording, windows: Windows, run: WindowRun, robots: list[RobotParams],
                   world: World | None, unjudged: np.ndarray | None = None,
                   far: np.ndarray | None = None) -> list[Channel]:
    """Every channel the recording supports: recorded vs the twin's run (and its sensors on the track).

    unjudged: (W, T - 1, S) IR readings that are not judged (windows.unjudged_readings): there the twin is
    given the recorded value, so they weigh nothing in a fit, a location or a fit %.  far: (W, T - 1, S)
    IR readings of a wall beyond the calibrated range (windows.IR_CALIBRATED_RANGE), held against the
    twin's reading there (IR_EXTRAPOLATED_TOLERANCE) where a bias is located."""
    p = robots[0]
    idx = windows.index
    chans: list[Channel] = []
    enc_rec = np.diff(rec.enc[idx], axis=1).astype(float)
    enc_twin = np.diff(run.enc, axis=2).astype(float)
    for w, name in enumerate(WHEELS):
        # The recorded counts are floors, the twin's are not: an increment is off by up to a tick (1/6 tick^2).
        chans.append(Channel(name, "ticks/period", enc_rec[..., w], enc_twin[..., w], float(np.sqrt(1 / 6))))
    if rec.pose is not None:
        if not rec.bench:  # on a bench the body is held: its motion says nothing of the drive
            chans += _motion_channels(rec, idx, run, p)
        if world is not None and world.n_walls and ring_comparable(rec, p):
            chans += sensor_channels(rec, idx[:, 1:], robots, world, unjudged, far)
    if not rec.battery_recorded:
        return chans
    vb = rec.vbat[idx[:, 1:]]
    vb_twin = (run.vbat[..., 1:] if run.vbat is not None
               else np.repeat(np.full_like(vb, p.battery_voltage)[:, None], run.enc.shape[1], 1))
    chans.append(Channel("vbat", "V", vb, vb_twin, 0.005, relative=False))
    return chans


def ring_comparable(rec: Recording, p: RobotParams) -> bool:
    """The recording's IR readings are the twin's ring's (ir_bearings): as many pairs, emitters on and ambient."""
    return rec.n_ir == len(p.ir_bearings) and rec.ambient_recorded


def _motion_channels(rec: Recording, idx: np.ndarray, run: WindowRun, p: RobotParams) -> list[Channel]:
    assert rec.pose is not None
    m_rec = _motion(rec.pose[idx])
    m_twin = _motion(run.pose)
    tick = 2 * np.pi * p.wheel_radius / p.ticks_per_rev  # m of rim per encoder tick
    floors = (0.5 * tick, 0.5 * tick, 0.5 * tick / (2 * p.half_axle))
    chans = [Channel(name, unit, m_rec[..., k], m_twin[..., k], floors[k])
             for k, (name, unit) in enumerate(zip(MOTION, ("m/period", "m/period", "rad/period")))]
    end_rec = rec.pose[idx[:, -1]]
    for k, name in enumerate(("x", "y", "phi")):
        chans.append(Channel(f"pose_{name}", "m" if k < 2 else "rad", end_rec[:, k:k + 1].copy(),
                             run.pose[:, :, -1:, k], 0.0, locate=False))
    return chans


def sensor_channels(rec: Recording, rows: np.ndarray, robots: list[RobotParams], world: World,
                    unjudged: np.ndarray | None, far: np.ndarray | None = None) -> list[Channel]:
    """The IR and ambient channels at the rows (W, T - 1): the twin's sensors on the recorded track, so
    whatever the twin's motion (no run needed); far as build_channels'."""
    on, amb = sensors_on_track(rec, rows, robots, world)  # (N, W, T - 1, S)
    p = robots[0]
    refl_rec = (rec.ir_on - rec.ir_amb)[rows].astype(float)
    refl_twin = (on - amb).astype(float).transpose(1, 0, 2, 3)
    if unjudged is not None:
        refl_twin = np.where(unjudged[:, None], refl_rec[:, None], refl_twin)
    amb_twin = amb.astype(float).transpose(1, 0, 2, 3)
    lamps = np.abs(amb_twin[:, 0] - ir_sensor.room_ambient(world, p))
    chans = []
    for k in range(rec.n_ir):
        far_scale = None if far is None else _extrapolated_scale(refl_rec[..., k], refl_twin[:, 0, ..., k], far[..., k])
        chans.append(Channel(IR[k], "counts", refl_rec[..., k], refl_twin[..., k], float(np.sqrt(2) * p.ir_noise + 0.5),
                             tolerance=IR_RESPONSE_TOLERANCE, scale=far_scale))
        chans.append(Channel(AMBIENT[k], "counts", rec.ir_amb[rows][..., k].astype(float), amb_twin[..., k],
                             float(p.ir_noise + 0.5), tolerance=LAMP_RESPONSE_TOLERANCE, scale=lamps[..., k]))
    return chans


def _extrapolated_scale(y: np.ndarray, twin: np.ndarray, far: np.ndarray) -> np.ndarray:
    """The signal an IR reading's bias is held against: the recorded reading, and beyond the calibrated
    range at least the twin's own, scaled so that its share is IR_EXTRAPOLATED_TOLERANCE."""
    beyond = np.maximum(np.abs(y), np.abs(twin) * (IR_EXTRAPOLATED_TOLERANCE / IR_RESPONSE_TOLERANCE))
    return np.where(far, beyond, np.abs(y))


def fit_percent(y: np.ndarray, y_hat: np.ndarray) -> float:
    """100 (1 - |y - y_hat| / |y - mean(y)|): 100 a perfect twin, 0 no better than the mean, below 0 worse."""
    spread = float(np.linalg.norm(y - y.mean()))
    err = float(np.linalg.norm(y - y_hat))
    if spread == 0.0:
        return 100.0 if err == 0.0 else -np.inf
    return 100.0 * (1.0 - err / spread)


def rounding_ceiling(y: np.ndarray, y_hat: np.ndarray, seed: int = 0) -> float:
    """The fit % (as fit_percent judges y) of a twin whose motion is right, against encoders that round it:
    the twin's counts per window (W, T - 1 increments) rounded down from a random sub-tick phase.  A steady
    wheel moves a few ticks a period, so its rounding alone keeps the fit well below 100.  Optimistic under a
    speed loop, which answers each rounded count: there the rounding and the motion are not independent, as a
    random phase takes them to be (docs/proving-ground.md, the perfect twin)."""
    phase = np.random.default_rng(seed).random((y_hat.shape[0], 1))
    counts = np.concatenate([np.zeros((y_hat.shape[0], 1)), np.cumsum(y_hat, axis=1)], axis=1) + phase
    spread = float(np.linalg.norm(y - y.mean()))
    err = float(np.linalg.norm(np.diff(np.floor(counts), axis=1) - y_hat))
    return 100.0 * (1.0 - err / spread) if spread > 0.0 else -np.inf
