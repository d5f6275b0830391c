"""Recordings: what a robot commanded and sensed, one format for simulator and robot.

A recording is a CSV file plus a JSON sidecar (docs/recordings.md):

    t,cmd_l,cmd_r,enc_l,enc_r,ir_on_0,...,ir_on_7,ir_amb_0,...,ir_amb_7,vbat,x,y,phi

one row per control cycle: t in seconds; cmd_l, cmd_r the current references
in A; enc_l, enc_r cumulative encoder ticks; ir_on_i, ir_amb_i raw ADC counts
with the emitters on and off (sensor 0 = S1 front, counter-clockwise); vbat in
volts; x, y (m) and phi (rad) from an external tracker (the simulator's truth),
empty when there is none.  The sidecar `FILE.json` holds the robot
parameters, the world, the sample period, the units, the source and the
software version.

Rows are written and flushed one at a time: a killed recorder loses nothing
it had written.  `load_recording` checks every cell and says file, line and
column of anything wrong; a last line cut short is reported as such, never
silently dropped.
"""
from __future__ import annotations

import csv
import datetime
import io
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

FORMAT = "twinbot-recording"
VERSION = 1
COLUMNS = (["t", "cmd_l", "cmd_r", "enc_l", "enc_r"] + [f"ir_on_{i}" for i in range(8)]
           + [f"ir_amb_{i}" for i in range(8)] + ["vbat", "x", "y", "phi"])
UNITS = {"t": "s", "cmd_l": "A", "cmd_r": "A", "enc_l": "ticks", "enc_r": "ticks", "ir_on_i": "ADC counts",
         "ir_amb_i": "ADC counts", "vbat": "V", "x": "m", "y": "m", "phi": "rad"}
_INT_COLUMNS = {"enc_l", "enc_r", *(f"ir_on_{i}" for i in range(8)), *(f"ir_amb_{i}" for i in range(8))}
_POSE = ("x", "y", "phi")


class RecordingError(ValueError):
    """A recording is malformed; the message says file, line, column and problem."""


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    return Path(str(path) + ".json")


def _software_version() -> str:
    try:
        from importlib.metadata import version

        return f"twinbot {version('twinbot')}"
    except Exception:  # noqa: BLE001 - running from a plain checkout
        return "twinbot (unreleased)"


class RecordingWriter:
    """Writes rows as they come, flushed; the sidecar first, completed on close."""

    def __init__(self, path: str | os.PathLike[str], *, source: str, sample_period: float,
                 robot: dict[str, object] | None = None, world: object = None,
                 extra: dict[str, object] | None = None) -> None:
        self.path = Path(path)
        if not self.path.parent.exists():
            raise RecordingError(f"{self.path}: folder {self.path.parent} does not exist")
        self.meta: dict[str, object] = {
            "format": FORMAT, "version": VERSION, "source": source, "software": _software_version(),
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "sample_period": sample_period, "columns": COLUMNS, "units": UNITS,
            "robot": robot or {}, "world": world, "rows": None, "complete": False, **(extra or {}),
        }
        self._write_sidecar()
        self._file = open(self.path, "w", newline="", encoding="ascii")
        self._file.write(",".join(COLUMNS) + "\n")
        self._file.flush()
        self.rows = 0

    def _write_sidecar(self) -> None:
        sidecar_path(self.path).write_text(json.dumps(self.meta, indent=1, default=str) + "\n")

    def row(self, t: float, cmd: tuple[float, float], enc: tuple[int, int], ir_on: list[int] | tuple[int, ...],
            ir_amb: list[int] | tuple[int, ...], vbat: float,
            pose: tuple[float, float, float] | None = None) -> None:
        cells = [repr(float(t)), repr(float(cmd[0])), repr(float(cmd[1])), str(int(enc[0])), str(int(enc[1]))]
        cells += [str(int(v)) for v in ir_on] + [str(int(v)) for v in ir_amb] + [repr(float(vbat))]
        cells += [repr(float(v)) for v in pose] if pose is not None else ["", "", ""]
        self._file.write(",".join(cells) + "\n")
        self._file.flush()
        self.rows += 1

    def close(self) -> None:
        if self._file.closed:
            return
        self._file.close()
        self.meta["rows"] = self.rows
        self.meta["complete"] = True
        self._write_sidecar()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class Recording:
    """A loaded recording: arrays by column group, and the sidecar."""

    t: np.ndarray  # (n,) s
    cmd: np.ndarray  # (n, 2) A
    enc: np.ndarray  # (n, 2) ticks, int64
    ir_on: np.ndarray  # (n, 8) counts, int64
    ir_amb: np.ndarray  # (n, 8) counts, int64
    vbat: np.ndarray  # (n,) V
    pose: np.ndarray | None  # (n, 3) x, y, phi, or None without a tracker
    meta: dict[str, object] = field(default_factory=dict)
    path: Path | None = None

    def __len__(self) -> int:
        return len(self.t)

    @property
    def sample_period(self) -> float:
        return float(self.meta.get("sample_period") or (np.median(np.diff(self.t)) if len(self.t) > 1 else 0.0))


def load_recording(path: str | os.PathLike[str], *, require_sidecar: bool = True) -> Recording:
    path = Path(path)
    meta = _load_sidecar(path, require_sidecar)
    try:
        text = path.read_text(encoding="ascii")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror}") from exc
    except UnicodeDecodeError as exc:
        raise RecordingError(f"{path}: not a recording (not ASCII text)") from exc
    if not text:
        raise RecordingError(f"{path}: empty file (no header)")
    lines = text.split("\n")
    if lines[-1] != "":
        raise RecordingError(f"{path}:{len(lines)}: last line is cut short (the recorder stopped mid-write); "
                             f"the {len(lines) - 2} rows before it are complete")
    lines.pop()
    header = lines[0].split(",")
    if header != COLUMNS:
        missing = [c for c in COLUMNS if c not in header]
        extra = [c for c in header if c not in COLUMNS]
        detail = []
        if missing:
            detail.append("missing " + ", ".join(missing))
        if extra:
            detail.append("unexpected " + ", ".join(extra))
        if not detail:
            detail.append("columns out of order")
        raise RecordingError(f"{path}:1: header is not the recording header ({'; '.join(detail)}); "
                             f"expected: {','.join(COLUMNS)}")
    n = len(lines) - 1
    data = np.zeros((n, len(COLUMNS)))
    has_pose = None
    adc_max = None
    robot = meta.get("robot") if isinstance(meta.get("robot"), dict) else None
    if robot and "adc_bits" in robot:
        adc_max = (1 << int(robot["adc_bits"])) - 1  # type: ignore[call-overload]
    for row_index, cells in enumerate(csv.reader(io.StringIO("\n".join(lines[1:])))):
        lineno = row_index + 2
        if len(cells) != len(COLUMNS):
            raise RecordingError(f"{path}:{lineno}: {len(cells)} cells, expected {len(COLUMNS)}")
        pose_cells = cells[-3:]
        empty = [c == "" for c in pose_cells]
        if any(empty) and not all(empty):
            raise RecordingError(f"{path}:{lineno}: x, y, phi must be all present or all empty")
        row_pose = not all(empty)
        if has_pose is None:
            has_pose = row_pose
        elif has_pose != row_pose:
            raise RecordingError(f"{path}:{lineno}: the tracker pose (x, y, phi) is "
                                 f"{'present' if row_pose else 'missing'} here but not in the rows before")
        for k, (name, cell) in enumerate(zip(COLUMNS, cells)):
            if name in _POSE and not row_pose:
                data[row_index, k] = math.nan
                continue
            try:
                value = int(cell) if name in _INT_COLUMNS else float(cell)
            except ValueError:
                kind = "an integer" if name in _INT_COLUMNS else "a number"
                raise RecordingError(f"{path}:{lineno}: column '{name}': {cell!r} is not {kind}") from None
            if not math.isfinite(value):
                raise RecordingError(f"{path}:{lineno}: column '{name}': {cell!r} is not finite")
            if name.startswith("ir_") and (value < 0 or (adc_max is not None and value > adc_max)):
                raise RecordingError(f"{path}:{lineno}: column '{name}': {value} is outside the ADC range "
                                     f"0..{adc_max if adc_max is not None else '?'}")
            data[row_index, k] = value
        if row_index and data[row_index, 0] <= data[row_index - 1, 0]:
            raise RecordingError(f"{path}:{lineno}: column 't': {cells[0]} does not increase "
                                 f"(previous row: {data[row_index - 1, 0]!r})")
    if meta.get("rows") is not None and meta.get("rows") != n:
        raise RecordingError(f"{path}: the sidecar says {meta['rows']} rows, the file holds {n}")
    col = {name: k for k, name in enumerate(COLUMNS)}
    return Recording(
        t=data[:, 0].copy(),
        cmd=data[:, [col["cmd_l"], col["cmd_r"]]].copy(),
        enc=data[:, [col["enc_l"], col["enc_r"]]].astype(np.int64),
        ir_on=data[:, col["ir_on_0"]:col["ir_on_7"] + 1].astype(np.int64),
        ir_amb=data[:, col["ir_amb_0"]:col["ir_amb_7"] + 1].astype(np.int64),
        vbat=data[:, col["vbat"]].copy(),
        pose=data[:, [col["x"], col["y"], col["phi"]]].copy() if has_pose else None,
        meta=meta, path=path,
    )


def _load_sidecar(path: Path, required: bool) -> dict[str, object]:
    side = sidecar_path(path)
    if not side.exists():
        if required:
            raise RecordingError(f"{side}: the sidecar of {path.name} is missing (it holds the robot parameters, "
                                 f"the world and the sample period)")
        return {}
    try:
        meta = json.loads(side.read_text())
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{side}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise RecordingError(f"{side}: not a twinbot recording sidecar (format must be '{FORMAT}')")
    if meta.get("version") != VERSION:
        raise RecordingError(f"{side}: recording version {meta.get('version')!r}, this twinbot reads {VERSION}")
    period = meta.get("sample_period")
    if not isinstance(period, (int, float)) or period <= 0:
        raise RecordingError(f"{side}: 'sample_period' must be a positive number of seconds, got {period!r}")
    return meta
