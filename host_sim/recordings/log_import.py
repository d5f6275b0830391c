"""A robot's own log (its columns and units) as a recording: what `twinbot import` does (docs/recordings.md, "Import").

A MAP (JSON) names the log's columns and units; everything is read and checked before anything is
written, and a bad MAP or LOG is one line naming the file, the line or key, and the problem.
Timing (gaps, repeated times, resets) is for the recording's loading checks, not for the import.
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from host_sim.physics.params import DRIVE_UNITS, PWM_DECAYS, ParamsError, RobotParams, params_from_dict, read_json
from host_sim.recordings.recording import MAX_IR, UNITS, RecordingWriter

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180, "turn/2^30": 2 * math.pi / (1 << 30)}
SPEED_UNITS = {"m/s": 1.0, "mm/s": 1e-3}
VOLT_UNITS = {"V": 1.0, "mV": 1e-3}
# command.kind -> {the log's unit: factor to the drive's canonical unit}; duty divides by full_scale instead
COMMAND_UNITS = {"current": {"A": 1.0, "mA": 1e-3}, "voltage": VOLT_UNITS,
                 "wheel_speed": {"rad/s": 1.0, "rpm": 2 * math.pi / 60, "m/s": None}}
WHEEL_SPEED_UNITS = COMMAND_UNITS["wheel_speed"]
MAP_KEYS = ("time", "command", "encoder", "wheel_speed", "battery", "pose", "ir", "emitter", "firmware")


class LogImportError(ValueError):
    """A MAP, LOG or ROBOT file that cannot be imported; the message names the file, line or key, and the problem."""


@dataclass
class Log:
    """The log's header (names stripped of surrounding spaces) and its rows of cells."""

    path: Path
    header: list[str]
    rows: list[list[str]]

    def column(self, name: object, where: str) -> int:
        if not isinstance(name, str):
            raise LogImportError(f"{where}: a column name must be a string, got {name!r}")
        try:
            return self.header.index(name.strip())
        except ValueError:
            raise LogImportError(f"{where}: no column {name.strip()!r} in {self.path} (its columns: "
                                 f"{', '.join(self.header)})") from None

    def numbers(self, name: object, where: str, empty_ok: bool = False) -> np.ndarray:
        """(n,) the column's cells as numbers (NaN where empty, if empty_ok)."""
        k = self.column(name, where)
        out = np.empty(len(self.rows))
        for i, row in enumerate(self.rows):
            cell = row[k].strip()
            if cell == "" and empty_ok:
                out[i] = math.nan
                continue
            try:
                out[i] = float(cell)
            except ValueError:
                out[i] = math.nan
            if not math.isfinite(out[i]):
                raise LogImportError(f"{self.path}:{i + 2}: column {self.header[k]!r}: {cell!r} is not a number")
        return out


@dataclass
class Imported:
    """What the recording's rows and sidecar will hold."""

    t: np.ndarray
    cmd: np.ndarray
    enc: np.ndarray
    ir_on: np.ndarray
    ir_amb: np.ndarray | None
    vbat: np.ndarray | None
    pose: np.ndarray | None
    emitter: np.ndarray | None
    firmware: np.ndarray | None
    robot: dict[str, object]
    drive: dict[str, object]


def read_log(path: str | os.PathLike[str]) -> Log:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise LogImportError(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise LogImportError(f"{path}: not a CSV log: byte {exc.start} is not UTF-8 text") from None
    rows = [r for r in csv.reader(text.splitlines())]
    if not rows or not any(c.strip() for c in rows[0]):
        raise LogImportError(f"{path}:1: no header (the first line names the columns)")
    header = [c.strip() for c in rows[0]]
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:
        raise LogImportError(f"{path}:1: column {twice[0]!r} is named twice")
    body = rows[1:]
    while body and not any(c.strip() for c in body[-1]):
        body.pop()  # trailing blank lines
    for i, row in enumerate(body):
        if len(row) != len(header):
            raise LogImportError(f"{path}:{i + 2}: {len(row)} cells, the header names {len(header)}")
    if len(body) < 2:
        raise LogImportError(f"{path}: {len(body)} rows; a recording needs 2 at least")
    return Log(path, header, body)


def read_json_object(path: str | os.PathLike[str], what: str) -> dict[str, object]:
    """A JSON file holding an object (a robot parameter file, a MAP); LogImportError says why not."""
    data = read_json(path, what, LogImportError)
    if not isinstance(data, dict):
        raise LogImportError(f"{path}: a {what} is a JSON object")
    return data


def load_robot(path: str | os.PathLike[str]) -> tuple[RobotParams, dict[str, object]]:
    """(the twin's parameters, the robot block for the sidecar)."""
    data = read_json_object(path, "robot parameter file")
    try:
        return params_from_dict(data, str(path)), dict(data)
    except ParamsError as exc:
        raise LogImportError(str(exc)) from None


class MapReader:
    """Reads MAP entries, each error naming the MAP file and the entry (e.g. "command.kind")."""

    def __init__(self, path: str | os.PathLike[str], data: dict[str, object]) -> None:
        self.path = Path(path)
        self.data = data
        unknown = [k for k in data if k not in MAP_KEYS]
        if unknown:
            raise LogImportError(f"{self.path}: unknown entry {unknown[0]!r} (a MAP holds {', '.join(MAP_KEYS)})")

    def where(self, *keys: str) -> str:
        return f"{self.path}: {'.'.join(keys)}"

    def group(self, key: str, required: bool = False) -> dict[str, object] | None:
        value = self.data.get(key)
        if value is None and not required:
            return None
        if not isinstance(value, dict):
            raise LogImportError(f"{self.where(key)}: {'missing; ' if value is None else ''}"
                                 f"an object naming the log's columns is needed here")
        return value

    def choice(self, group: dict[str, object], gname: str, key: str, choices: dict[str, object] | tuple[str, ...],
               default: str | None = None) -> str:
        value = group.get(key, default)
        if value not in choices:
            said = "missing" if value is None else f"{value!r} is not known"
            raise LogImportError(f"{self.where(gname, key)}: {said}; one of {', '.join(choices)}")
        return str(value)

    def number(self, group: dict[str, object], gname: str, key: str, positive: bool = True) -> float:
        value = group.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or (
                positive and value <= 0):
            raise LogImportError(f"{self.where(gname, key)}: a {'positive ' if positive else ''}number is needed, "
                                 f"got {value!r}")
        return float(value)


def convert(log: Log, m: MapReader, params: RobotParams, robot: dict[str, object]) -> Imported:
    """The log's rows in the recording's columns and units."""
    t = _time(log, m)
    cmd, drive, robot = _command(log, m, params, robot)
    enc = _wheels(log, m, params, t)
    ir_on, ir_amb = _ir(log, m, params)
    if "ir_bearings" in robot and ir_on.shape[1] != len(params.ir_bearings):
        raise LogImportError(f"{m.where('ir', 'on')}: {ir_on.shape[1]} sensors, but the robot file's ir_bearings "
                             f"places {len(params.ir_bearings)} pairs")
    pose = _pose(log, m)
    return Imported(t, cmd, enc, ir_on, ir_amb, _battery(log, m), pose, _emitter(log, m), _firmware(log, m),
                    robot, drive)


def _time(log: Log, m: MapReader) -> np.ndarray:
    g = m.group("time", required=True)
    assert g is not None
    unit = m.choice(g, "time", "unit", TIME_UNITS)
    return scaled(log.numbers(g.get("column"), m.where("time", "column")), TIME_UNITS[unit])


def scaled(values: np.ndarray, factor: float) -> np.ndarray:
    """values * factor, dividing by 1/factor where that is whole, so that 9 ms reads 0.009 s, not 0.009000000000000001."""
    inverse = 1.0 / factor
    return values / inverse if inverse == round(inverse) else values * factor


def _command(log: Log, m: MapReader, params: RobotParams, robot: dict[str, object]
             ) -> tuple[np.ndarray, dict[str, object], dict[str, object]]:
    """(n, 2) commands in the drive's canonical unit, the sidecar's drive block, the robot block with `drive`."""
    g = m.group("command", required=True)
    assert g is not None
    kind = m.choice(g, "command", "kind", DRIVE_UNITS)
    raw = np.column_stack([log.numbers(g.get(s), m.where("command", s)) for s in ("left", "right")])
    full_scale = None
    if kind == "duty":
        full_scale = m.number(g, "command", "full_scale")
        source_unit = str(g.get("unit", "counts"))
        cmd = raw / full_scale
        beyond = np.flatnonzero(np.abs(cmd).max(axis=1) > 1.0)
        if len(beyond):
            k = int(beyond[0])
            raise LogImportError(f"{log.path}:{k + 2}: command {raw[k, 0]:g}/{raw[k, 1]:g} is beyond full_scale "
                                 f"{full_scale:g} (a duty is at most the full scale)")
    else:
        source_unit = m.choice(g, "command", "unit", COMMAND_UNITS[kind])
        factor = COMMAND_UNITS[kind][source_unit]
        cmd = scaled(raw, factor) if factor is not None else raw / params.wheel_radius
    robot = _robot_drive(m, g, kind, robot)
    return cmd, {"kind": kind, "unit": DRIVE_UNITS[kind], "source_unit": source_unit, "full_scale": full_scale}, robot


def _robot_drive(m: MapReader, g: dict[str, object], kind: str, robot: dict[str, object]) -> dict[str, object]:
    """The robot block with the MAP's drive (and decay) in it; a ROBOT file that says otherwise is refused."""
    robot = dict(robot)
    said = robot.get("drive", kind)  # a robot file silent on its drive takes the MAP's
    if said != kind:
        raise LogImportError(f"{m.where('command', 'kind')}: {kind!r}, but the robot file says drive {said!r}")
    if kind != "current":
        robot["drive"] = kind
    if "decay" in g:
        if kind not in ("voltage", "duty"):
            raise LogImportError(f"{m.where('command', 'decay')}: a {kind} drive has no PWM decay")
        decay = m.choice(g, "command", "decay", PWM_DECAYS)
        if robot.get("pwm_decay", decay) != decay:
            raise LogImportError(f"{m.where('command', 'decay')}: {decay!r}, but the robot file says pwm_decay "
                                 f"{robot['pwm_decay']!r}")
        robot["pwm_decay"] = decay
    return robot


def _wheels(log: Log, m: MapReader, params: RobotParams, t: np.ndarray) -> np.ndarray:
    """(n, 2) cumulative encoder counts: the log's, or its wheel speeds integrated (trapezoids, from 0)."""
    enc_g, speed_g = m.group("encoder"), m.group("wheel_speed")
    if (enc_g is None) == (speed_g is None):
        raise LogImportError(f"{m.path}: the wheels: give either 'encoder' (counts) or 'wheel_speed' "
                             f"(speeds), {'not both' if enc_g else 'one is needed'}")
    if enc_g is not None:
        counts = np.column_stack([log.numbers(enc_g.get(s), m.where("encoder", s)) for s in ("left", "right")])
        bad = np.argwhere(counts != np.round(counts))
        if len(bad):
            raise LogImportError(f"{log.path}:{bad[0, 0] + 2}: encoder {counts[bad[0, 0], bad[0, 1]]!r} is not a "
                                 f"whole count")
        return counts.astype(np.int64)
    assert speed_g is not None
    unit = m.choice(speed_g, "wheel_speed", "unit", WHEEL_SPEED_UNITS)
    factor = WHEEL_SPEED_UNITS[unit]
    speed = np.column_stack([log.numbers(speed_g.get(s), m.where("wheel_speed", s)) for s in ("left", "right")])
    speed = speed * (factor if factor is not None else 1.0 / params.wheel_radius)  # rad/s of the wheel
    angle = np.vstack([np.zeros((1, 2)), np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t)[:, None], axis=0)])
    tpr = np.array([params.ticks_per_rev + params.ticks_per_rev_delta_l,
                    params.ticks_per_rev + params.ticks_per_rev_delta_r])
    return np.floor(angle / (2 * math.pi) * tpr[None, :]).astype(np.int64)


def _ir(log: Log, m: MapReader, params: RobotParams) -> tuple[np.ndarray, np.ndarray | None]:
    """(n, S) emitter-on readings and (n, S) ambient ones (None if the log has none), rounded to counts."""
    g = m.group("ir")
    if g is None:
        return np.zeros((len(log.rows), 0), np.int64), None
    on_names, amb_names = g.get("on"), g.get("ambient")
    if not isinstance(on_names, list) or not 0 < len(on_names) <= MAX_IR:
        raise LogImportError(f"{m.where('ir', 'on')}: a list of 1..{MAX_IR} column names is needed, one a sensor")
    if amb_names is not None and (not isinstance(amb_names, list) or len(amb_names) != len(on_names)):
        raise LogImportError(f"{m.where('ir', 'ambient')}: a list of {len(on_names)} column names is needed, "
                             f"one for each of ir.on")

    def readings(names: list[object], key: str) -> np.ndarray:
        cols = [log.numbers(c, m.where("ir", key)) for c in names]
        out = np.round(np.column_stack(cols)).astype(np.int64)
        bad = np.argwhere((out < 0) | (out > params.adc_max))
        if len(bad):
            row, k = (int(v) for v in bad[0])
            raise LogImportError(f"{log.path}:{row + 2}: column {str(names[k]).strip()!r}: {out[row, k]} is outside "
                                 f"the ADC range 0..{params.adc_max} (the robot file's adc_bits)")
        return out

    return readings(on_names, "on"), None if amb_names is None else readings(amb_names, "ambient")


def _column_or_value(log: Log, m: MapReader, key: str, units: dict[str, float] | None) -> np.ndarray | None:
    """A group given as {"column": name} or {"value": number}, with "unit" from units (None: no unit)."""
    g = m.group(key)
    if g is None:
        return None
    factor = units[m.choice(g, key, "unit", units)] if units is not None else 1.0
    if ("column" in g) == ("value" in g):
        raise LogImportError(f"{m.where(key)}: give either 'column' or 'value'")
    if "value" in g:
        return scaled(np.full(len(log.rows), m.number(g, key, "value", positive=False)), factor)
    return scaled(log.numbers(g["column"], m.where(key, "column")), factor)


def _battery(log: Log, m: MapReader) -> np.ndarray | None:
    return _column_or_value(log, m, "battery", VOLT_UNITS)


def _emitter(log: Log, m: MapReader) -> np.ndarray | None:
    return _column_or_value(log, m, "emitter", None)


def _pose(log: Log, m: MapReader) -> np.ndarray | None:
    """(n, 3) the tracker pose in m, m, rad; NaN rows where the log's three cells are empty."""
    g = m.group("pose")
    if g is None:
        return None
    length = LENGTH_UNITS[m.choice(g, "pose", "unit", LENGTH_UNITS)]
    angle = ANGLE_UNITS[m.choice(g, "pose", "angle_unit", ANGLE_UNITS)]
    pose = np.column_stack([log.numbers(g.get(c), m.where("pose", c), empty_ok=True) for c in ("x", "y", "phi")])
    partial = np.flatnonzero(np.isnan(pose).any(axis=1) & ~np.isnan(pose).all(axis=1))
    if len(partial):
        raise LogImportError(f"{log.path}:{partial[0] + 2}: the pose's x, y and phi must be all given or all empty")
    return np.column_stack([scaled(pose[:, 0], length), scaled(pose[:, 1], length), scaled(pose[:, 2], angle)])


def _firmware(log: Log, m: MapReader) -> np.ndarray | None:
    """(n, 6) the firmware's view: mode, set-points (m/s), odometry (m, m, rad)."""
    g = m.group("firmware")
    if g is None:
        return None
    speed = SPEED_UNITS[m.choice(g, "firmware", "speed_unit", SPEED_UNITS)]
    length = LENGTH_UNITS[m.choice(g, "firmware", "unit", LENGTH_UNITS)]
    angle = ANGLE_UNITS[m.choice(g, "firmware", "angle_unit", ANGLE_UNITS)]
    scale = (1.0, speed, speed, length, length, angle)
    cols = [scaled(log.numbers(g.get(c), m.where("firmware", c)), f)
            for c, f in zip(("mode", "sp_l", "sp_r", "odo_x", "odo_y", "odo_phi"), scale)]
    view = np.column_stack(cols)
    view[:, 5] = np.angle(np.exp(1j * view[:, 5]))  # (-pi, pi], as the firmware's heading is recorded
    return view


def write(imported: Imported, out: str | os.PathLike[str], log_path: Path) -> int:
    """Write the recording (rows, then the completed sidecar); the number of rows."""
    n = len(imported.t)
    period = round(float(np.median(np.diff(imported.t))), 9)  # a whole number of microseconds, not float noise
    units = {**UNITS, "cmd_l": imported.drive["unit"], "cmd_r": imported.drive["unit"]}
    extra: dict[str, object] = {"drive": imported.drive, "units": units, "imported_from": log_path.name}
    if imported.pose is not None:
        extra["tracker_gaps"] = True
    with RecordingWriter(out, source="robot", sample_period=period, robot=imported.robot, extra=extra,
                         n_ir=imported.ir_on.shape[1]) as writer:
        for k in range(n):
            pose = None if imported.pose is None or np.isnan(imported.pose[k]).any() else tuple(imported.pose[k])
            firmware = None if imported.firmware is None else (int(imported.firmware[k, 0]),
                                                               *imported.firmware[k, 1:].tolist())
            writer.row(float(imported.t[k]), tuple(imported.cmd[k]), tuple(imported.enc[k]),  # type: ignore[arg-type]
                       imported.ir_on[k].tolist(), None if imported.ir_amb is None else imported.ir_amb[k].tolist(),
                       None if imported.vbat is None else float(imported.vbat[k]), pose,  # type: ignore[arg-type]
                       emitter_pct=None if imported.emitter is None else float(imported.emitter[k]),
                       firmware=firmware)  # type: ignore[arg-type]
    return n


def import_log(log_path: str | os.PathLike[str], map_path: str | os.PathLike[str],
               robot_path: str | os.PathLike[str], out: str | os.PathLike[str]) -> Imported:
    """Read and check LOG, MAP and ROBOT, then write the recording OUT (and OUT.json)."""
    mapping = MapReader(map_path, read_json_object(map_path, "MAP"))
    params, robot = load_robot(robot_path)
    log = read_log(log_path)
    imported = convert(log, mapping, params, robot)
    write(imported, out, Path(log_path))
    return imported
