"""What loading checks: a recording's timing, encoders and units, named or refused, never fitted as physics.

`check_recording(rec, params)` returns the recording with repeated rows dropped and wrapped clocks and
encoders unwrapped, its `notes` naming each with rows and times; or raises `RecordingCheckError`, one
line naming the likely cause and the fix.  The thresholds come from the robot's physics and the
recording's own period: docs/recordings.md, "What loading checks".
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from host_sim.physics import dynamics, motors
from host_sim.physics.params import RobotParams
from host_sim.recordings.recording import _UNWRAP_LIMIT, Recording, RecordingError

LATE_PERIODS = 1.5  # a step longer than this many periods: a row came late or is missing
# Clocks a log may hold raw, by how far they go back when they wrap (s): a 16-bit ms counter, MicroPython's
# ticks_ms (2^30 ms), signed and unsigned 32-bit ms, and a 32-bit microsecond counter.
CLOCK_WRAPS_S = (2 ** 16 / 1e3, 2 ** 30 / 1e3, 2 ** 31 / 1e3, 2 ** 32 / 1e3, 2 ** 32 / 1e6)
ENCODER_BITS = (32, 16)  # the counters an encoder value wraps in, the wider first (2^32 is a multiple of 2^16)
SPEED_MARGIN = 2.0  # a wheel turns at most this many times its top speed (a push, a slope) between rows
ROUNDING_TICKS = 2  # ... plus the rounding of both rows' counts
UNIT_FACTOR = 10.0  # a command or a tracked speed this many times its physical bound is in another unit
MIN_SIGN_ROWS = 50  # rows where a wheel and its command both are clear of friction and rounding
MIN_SIGN_AGREEMENT = 0.3  # share of them turning with the command; below: the encoder's sign is flipped
NOTE_ROWS_SHOWN = 5  # rows a note spells out, the others counted


class RecordingCheckError(RecordingError):
    """The recording is refused; one line says where, the likely cause and the fix."""


@dataclass(frozen=True)
class Note:
    """Something loading found and mended; rows count from 0, the header not counted (file line = row + 2)."""

    name: str  # repeated_rows, clock_wrap, late_rows, encoder_wrap
    text: str
    rows: tuple[int, ...]
    times: tuple[float, ...]  # s, as recorded (after the clock's unwrapping)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "text": self.text, "rows": list(self.rows),
                "times": [round(t, 4) for t in self.times]}


def top_speed(p: RobotParams) -> float:
    """rad/s of a wheel whose motor's back-EMF equals the battery voltage: no drive turns it faster."""
    return float(p.battery_voltage / (p.torque_constant * p.gear_ratio))


def speed_memory(p: RobotParams) -> float:
    """s: the time constant of the robot's speed with its drive holding the current, J / c_v (the larger
    of the wheels' two modes, together and in opposition); without viscous friction, the time dry friction
    takes to stop it from its top speed."""
    m_t, j_t = dynamics.effective_inertias(p)
    r, b = p.wheel_radius, p.half_axle
    inertia = max(float(m_t) * r * r / 2, float(j_t) * r * r / (2 * b * b))
    if p.viscous_friction > 0:
        return inertia / p.viscous_friction
    return inertia * top_speed(p) / p.coulomb_friction if p.coulomb_friction > 0 else math.inf


def check_recording(rec: Recording, p: RobotParams) -> Recording:
    """The recording mended (repeated rows dropped, clocks and encoders unwrapped) with its notes; raises
    RecordingCheckError on what cannot be mended (tests/test_recording_checks.py)."""
    where = str(rec.path or "recording")
    check_resets(rec, where)
    keep, t, notes = check_times(rec.t, speed_memory(p), where)
    rec = _rows(rec, keep, t)
    enc, enc_notes = check_encoders(rec, np.flatnonzero(keep), p, where)
    rec = dataclasses.replace(rec, enc=enc)
    check_units(rec, p, where)
    return dataclasses.replace(rec, notes=[*rec.notes, *notes, *enc_notes])


def check_resets(rec: Recording, where: str) -> None:
    """Refuse a recording whose recorder saw the robot's clock go back (the sidecar's clock_resets): the
    board restarted there, its encoders and odometry count again from 0, and a step across it is no physics
    (nor a counter wrap) to replay (tests/test_recording_checks.py)."""
    resets = rec.meta.get("clock_resets") or []
    if not isinstance(resets, list) or not all(isinstance(k, int) and 0 <= k < len(rec) for k in resets):
        raise RecordingCheckError(f"{where}: the sidecar's clock_resets must list row numbers of the recording, "
                                  f"got {resets!r}")
    if resets:
        k = resets[0]
        more = f", {len(resets) - 1} more after it" if len(resets) > 1 else ""
        raise RecordingCheckError(
            f"{where}: row {k} (t {rec.t[k]:.3f} s): the robot restarted just before it (its clock was reset: the "
            f"sidecar's clock_resets{more}): its encoders and odometry count again from 0 there; cut the recording "
            f"there and use each part")


def _rows(rec: Recording, keep: np.ndarray, t: np.ndarray) -> Recording:
    """rec's rows where keep, with times t."""
    if keep.all() and np.array_equal(t, rec.t):
        return rec
    arrays = {f.name: getattr(rec, f.name)[keep] for f in dataclasses.fields(rec)
              if isinstance(getattr(rec, f.name), np.ndarray) and len(getattr(rec, f.name)) == len(keep)
              and f.name != "t"}
    return dataclasses.replace(rec, t=t, **arrays)


def _note(name: str, text: str, rows: np.ndarray, times: np.ndarray, details: list[str] | None = None) -> Note:
    """A note whose text's {where} reads 'rows 3 (t 0.120 s), 9 (t 0.360 s) and 4 more', a detail per row."""
    shown = [f"{int(k)} (t {x:.3f} s" + (f", {details[i]}" if details else "") + ")"
             for i, (k, x) in enumerate(zip(rows[:NOTE_ROWS_SHOWN], times))]
    more = f" and {len(rows) - NOTE_ROWS_SHOWN} more" if len(rows) > NOTE_ROWS_SHOWN else ""
    where = ("row " if len(rows) == 1 else "rows ") + ", ".join(shown) + more
    return Note(name, text.format(where=where), tuple(int(k) for k in rows), tuple(float(x) for x in times))


def check_times(t: np.ndarray, memory: float, where: str) -> tuple[np.ndarray, np.ndarray, list[Note]]:
    """(rows kept, their times, notes): repeated times dropped, wrapped clocks unwrapped, late rows noted;
    a clock reset, or rows farther apart than the speed's memory, refused."""
    notes: list[Note] = []
    keep = np.ones(len(t), dtype=bool)
    keep[1:] = np.diff(t) != 0
    repeated = np.flatnonzero(~keep)
    if len(repeated):
        notes.append(_note("repeated_rows", f"{len(repeated)} row(s) repeat the time of the row before, {{where}}: "
                           f"dropped, the first of each kept", repeated, t[repeated]))
    rows = np.flatnonzero(keep)
    t, wraps = _unwrap_clock(t[keep], rows, memory, where)
    if wraps:
        at = np.array(wraps)
        notes.append(_note("clock_wrap", "the clock wraps at {where}: unwrapped", rows[at], t[at]))
    if len(t) > 2:
        notes += _check_steps(t, rows, memory, where)
    return keep, t, notes


def _unwrap_clock(t: np.ndarray, rows: np.ndarray, memory: float, where: str) -> tuple[np.ndarray, list[int]]:
    """Times with each step back that a clock's wrap explains unwrapped; another step back, or a step
    forward the robot's clock unwrapping reads as a reset, is refused."""
    t = t.copy()
    wraps = []
    for k in np.flatnonzero(np.diff(t) < 0) + 1:
        step = float(t[k] - t[k - 1])
        # read as a wrap only if the step it leaves is one the dynamics allow and under half the wrap
        wrap = next((w for w in CLOCK_WRAPS_S if 0 < step + w <= min(memory, w / 2)), None)
        if wrap is None:
            raise RecordingCheckError(
                f"{where}: row {rows[k]}: the clock goes back from {t[k - 1]:.3f} s to {t[k]:.3f} s, a reset (the "
                f"robot restarted?): the rows after it are another run; cut the recording there and use each part")
        t[k:] += wrap
        wraps.append(int(k))
    jumps = np.flatnonzero(np.diff(t) > _UNWRAP_LIMIT / 1000) + 1
    if len(jumps):
        k = int(jumps[0])
        raise RecordingCheckError(
            f"{where}: row {rows[k]}: the clock jumps {t[k] - t[k - 1]:.0f} s ahead, which the robot's clock "
            f"unwrapping reads as a reset (the robot restarted?); cut the recording there and use each part")
    return t, wraps


def _check_steps(t: np.ndarray, rows: np.ndarray, memory: float, where: str) -> list[Note]:
    """Refuse rows farther apart than the speed's memory; note the late ones (over LATE_PERIODS periods)."""
    steps = np.diff(t)
    period = float(np.median(steps))
    if period > memory:
        raise RecordingCheckError(
            f"{where}: rows {1000 * period:.0f} ms apart: too far apart for the robot's dynamics (its speed "
            f"forgets a push in {1000 * memory:.0f} ms, J/c_v); record a row every control period")
    far = np.flatnonzero(steps > memory) + 1
    if len(far):
        k = int(far[0])
        raise RecordingCheckError(
            f"{where}: row {rows[k]} (t {t[k]:.3f} s) comes {1000 * steps[k - 1]:.0f} ms after the row before"
            + (f" ({len(far) - 1} more such gaps)" if len(far) > 1 else "") + f": too far apart for the robot's "
            f"dynamics (its speed forgets a push in {1000 * memory:.0f} ms, J/c_v); cut the recording there "
            f"and use each part")
    late = np.flatnonzero(steps > LATE_PERIODS * period) + 1
    if not len(late):
        return []
    return [_note("late_rows", f"{len(late)} row(s) late or after missing ones (over {LATE_PERIODS:g} periods of "
                  f"{1000 * period:.0f} ms after the row before), {{where}}: each replayed for its recorded duration",
                  rows[late], t[late], [f"{1000 * steps[k - 1]:.0f} ms after" for k in late])]


def check_encoders(rec: Recording, rows: np.ndarray, p: RobotParams, where: str) -> tuple[np.ndarray, list[Note]]:
    """(the counts with wraps at 16 or 32 bits undone, notes); a jump no wheel can turn is refused.
    rows: each of rec's rows' number in the file."""
    enc = rec.enc.copy()
    notes = []
    if len(rec) < 2:
        return enc, notes
    dt = np.diff(rec.t)
    for w, side in enumerate(("left", "right")):
        ticks = SPEED_MARGIN * top_speed(p) * dt * motors.ticks_per_rev(p, w) / (2 * math.pi) + ROUNDING_TICKS
        step, wraps = _unwrap_counter(np.diff(enc[:, w]), ticks)
        for bits, at in wraps:
            notes.append(_note("encoder_wrap", f"the {side} encoder (enc_{side[0]}) wraps at {bits} bits at "
                               "{where}: unwrapped", rows[at + 1], rec.t[at + 1]))
        jumps = np.flatnonzero(np.abs(step) > ticks)
        if len(jumps):
            k = int(jumps[0])
            raise RecordingCheckError(
                f"{where}: row {rows[k + 1]} (t {rec.t[k + 1]:.3f} s): the {side} encoder jumps {int(step[k])} ticks "
                f"in {1000 * dt[k]:.0f} ms, more than its wheel turns at {SPEED_MARGIN:g} times its top speed "
                f"({ticks[k]:.0f} ticks): a counter reset or a glitch; cut the recording there and use each part")
        if wraps:  # the first count in the widest wrapping counter's signed range: -500, not 65036
            span = 1 << wraps[0][0]
            enc[0, w] = (enc[0, w] + span // 2) % span - span // 2
        enc[1:, w] = enc[0, w] + np.cumsum(step)
    return enc, notes


def _unwrap_counter(step: np.ndarray, ticks: np.ndarray) -> tuple[np.ndarray, list[tuple[int, np.ndarray]]]:
    """(steps with each wrap undone, [(bits, the steps that wrapped at that many bits)], widest first): a
    step no wheel turns (over `ticks`) that is one it does turn modulo 2^bits."""
    wrapped = np.zeros(len(step), dtype=bool)
    wraps = []
    for bits in ENCODER_BITS:
        span = 1 << bits
        short = (step + span // 2) % span - span // 2
        fix = (np.abs(step) > ticks) & (np.abs(short) <= ticks) & ~wrapped
        if fix.any():
            step = np.where(fix, short, step)
            wrapped |= fix
            wraps.append((bits, np.flatnonzero(fix)))
    return step, wraps


def check_units(rec: Recording, p: RobotParams, where: str) -> None:
    """Refuse commands, a tracker pose or an encoder in a unit the twin does not read, naming the likely
    unit and the fix rather than guessing."""
    kind = rec.drive  # the recording's own drive, which replay and the diagnosis take (replay.with_drive)
    if kind == "current":
        _check_current(rec, p, where)
    elif kind == "duty" and len(rec) and np.abs(rec.cmd).max() > 1.0:
        raise RecordingCheckError(f"{where}: duty commands up to {np.abs(rec.cmd).max():g}: a duty is a fraction "
                                  f"in [-1, 1]; divide cmd_l, cmd_r by the duty's full scale")
    if rec.pose is not None:
        _check_pose(rec, p, where)
    _check_encoder_signs(rec, p, kind, where)


def _check_current(rec: Recording, p: RobotParams, where: str) -> None:
    """Currents far beyond the driver's limit: in mA (the wheels turn as a thousandth would), or wrong."""
    peak = float(np.abs(rec.cmd).max()) if len(rec) else 0.0
    if peak <= UNIT_FACTOR * p.current_limit:
        return
    speed = _wheel_speeds(rec, p)
    typical = float(np.percentile(np.abs(speed), 95)) if len(speed) else 0.0
    if peak / 1000 <= 2 * p.current_limit and typical < 0.5 * top_speed(p):
        raise RecordingCheckError(
            f"{where}: commands up to {peak:g} A, {peak / p.current_limit:.0f} times the current limit "
            f"{p.current_limit:g} A, while the wheels turn as a thousandth of that would (95 % of the time below "
            f"{100 * typical / top_speed(p):.0f} % of the top speed the limit drives them to): the commands are "
            f"likely in mA; give cmd_l, cmd_r in A (divide by 1000)")
    raise RecordingCheckError(
        f"{where}: commands up to {peak:g} A, {peak / p.current_limit:.0f} times the current limit "
        f"{p.current_limit:g} A: not currents in A (another unit, or another drive); give cmd_l, cmd_r in A or say "
        f"the drive in the sidecar")


def _wheel_speeds(rec: Recording, p: RobotParams) -> np.ndarray:
    """(n - 1, 2) rad/s of each wheel over each step, from the encoders."""
    if len(rec) < 2:
        return np.zeros((0, 2))
    per_tick = np.array([2 * math.pi / motors.ticks_per_rev(p, w) for w in range(2)])
    return np.diff(rec.enc, axis=0) * per_tick / np.diff(rec.t)[:, None]


def _check_pose(rec: Recording, p: RobotParams, where: str) -> None:
    """A tracker far faster than the robot can drive, or far outside its world: in mm (or cm).  Rows the
    tracker lost (empty) are left out."""
    assert rec.pose is not None
    fastest = top_speed(p) * p.wheel_radius
    speed = np.hypot(*(np.diff(rec.pose[:, :2], axis=0) / np.diff(rec.t)[:, None]).T)
    speed = speed[np.isfinite(speed)]
    typical = float(np.percentile(speed, 95)) if len(speed) else 0.0
    world = rec.meta.get("world")
    size = max(world["size"]) if isinstance(world, dict) and isinstance(world.get("size"), list) else None
    seen = np.abs(rec.pose[:, :2])
    extent = float(seen[np.isfinite(seen)].max(initial=0.0))
    if typical > UNIT_FACTOR * fastest:
        seen = f"the tracker moves at {typical:.3g} m/s, {typical / fastest:.0f} times the robot's top speed " \
               f"{fastest:.2f} m/s"
        ratio = typical / fastest
    elif size is not None and extent > UNIT_FACTOR * float(size):
        seen = f"the tracker's pose reaches {extent:.4g} m in a world {float(size):g} m across"
        ratio = extent / float(size)
    else:
        return
    unit = "mm (divide x and y by 1000)" if ratio > 100 else "cm (divide x and y by 100)"
    raise RecordingCheckError(f"{where}: {seen}: the pose is likely in {unit}; give x, y in m")


def _check_encoder_signs(rec: Recording, p: RobotParams, kind: str, where: str) -> None:
    """A wheel that turns against its commands nearly always: its encoder counts backwards.

    A drive turns its wheel against the command only while braking, and friction shortens that, so a
    wheel turns with its command in most of the rows where both are clear of friction and rounding."""
    speed = _wheel_speeds(rec, p)
    if not len(speed):
        return
    for w, side in enumerate(("left", "right")):
        cmd = rec.cmd[:-1, w]
        if kind == "current":  # the current that just overcomes the axle's dry friction
            clear = p.coulomb_friction / (p.gear_efficiency * p.gear_ratio * p.torque_constant)
        else:
            clear = 0.05 * float(np.abs(cmd).max())
        tick_speed = ROUNDING_TICKS * 2 * math.pi / motors.ticks_per_rev(p, w) / np.diff(rec.t)
        both = (np.abs(cmd) > clear) & (np.abs(speed[:, w]) > tick_speed)
        if both.sum() < MIN_SIGN_ROWS:
            continue
        agree = float((np.sign(cmd[both]) == np.sign(speed[both, w])).mean())
        if agree < MIN_SIGN_AGREEMENT:
            raise RecordingCheckError(
                f"{where}: the {side} wheel turns against its commands in {100 * (1 - agree):.0f} % of the "
                f"{int(both.sum())} rows where both are clear of friction and rounding: its encoder counts "
                f"backwards; negate enc_{side[0]} (or swap its encoder's A and B)")
