"""Recordings: what a robot commanded and sensed, one format for simulator and robot (docs/recordings.md).

A CSV file, one row per control cycle, plus a JSON sidecar.  One writer, `RecordingWriter`,
for every source: TELEMETRY through `telemetry()`, a robot with no firmware through `row()`;
rows are flushed one at a time, so a killed recorder loses nothing it had written.
`load_recording` checks every cell and names the file, line and column of anything wrong;
version 1 files still load.
"""
from __future__ import annotations

import contextlib
import csv
import datetime
import io
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from firmware.config import DEFAULT_CYCLE_MS
from firmware.hal import TICK_MASK
from firmware.odometry import HEADING_TURN
from host_sim.physics.params import DRIVE_UNITS, DRIVES, read_json

FORMAT = "twinbot-recording"
VERSION = 2
READABLE_VERSIONS = (1, 2)
FIRMWARE_IR = 8  # the firmware's ring; a recording of another robot holds 0..MAX_IR sensors
MAX_IR = 64


def ir_columns(n_ir: int = FIRMWARE_IR) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The emitter-on and ambient column names of n_ir sensors."""
    return tuple(f"ir_on_{i}" for i in range(n_ir)), tuple(f"ir_amb_{i}" for i in range(n_ir))


def columns(n_ir: int = FIRMWARE_IR) -> list[str]:
    """The header of a version-2 recording with n_ir IR sensors."""
    on, amb = ir_columns(n_ir)
    return ["t", "cmd_l", "cmd_r", "enc_l", "enc_r", *on, *amb, "vbat", "emitter_pct", *FIRMWARE_VIEW, *POSE]


IR_ON, IR_AMB = ir_columns()
FIRMWARE_VIEW = ("mode", "sp_l", "sp_r", "odo_x", "odo_y", "odo_phi")
POSE = ("x", "y", "phi")
COLUMNS_V1 = ["t", "cmd_l", "cmd_r", "enc_l", "enc_r", *IR_ON, *IR_AMB, "vbat", *POSE]
COLUMNS = columns()
UNITS = {"t": "s", "cmd_l": "A", "cmd_r": "A", "enc_l": "ticks", "enc_r": "ticks", "ir_on_i": "ADC counts",
         "ir_amb_i": "ADC counts", "vbat": "V", "emitter_pct": "%", "mode": "protocol MODE_*",
         "sp_l": "m/s", "sp_r": "m/s", "odo_x": "m", "odo_y": "m", "odo_phi": "rad",
         "x": "m", "y": "m", "phi": "rad"}
_INT_COLUMNS = {"enc_l", "enc_r", "mode"}
# Column groups that may be empty: all cells of a group present or all empty, in every row alike (the
# ambient readings are a group too, see _optional_groups).  The tracker pose may also be empty in some rows
# only, where the sidecar says "tracker_gaps": true (a tracker that lost the robot for a while).
_OPTIONAL_GROUPS = (("emitter_pct",), ("vbat",), FIRMWARE_VIEW, POSE)
_GROUP_LABELS = {("emitter_pct",): "the emitter power (emitter_pct)", ("vbat",): "the battery voltage (vbat)",
                 FIRMWARE_VIEW: "the firmware's view (" + ", ".join(FIRMWARE_VIEW) + ")",
                 POSE: "the tracker pose (x, y, phi)"}
_UNWRAP_LIMIT = 1 << 29  # ms: a larger forward jump of the robot's clock is a reset, not time passing


def _heading_rad(heading: int) -> float:
    """The firmware's heading (1/2^30 turn, wrapped to [0, 2^30)) in rad, in (-pi, pi]."""
    turns = heading / HEADING_TURN
    return 2 * math.pi * (turns - 1.0 if turns > 0.5 else turns)


class RecordingError(ValueError):
    """A recording is malformed (the message says file, line, column and problem), or could not be written."""


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
                 extra: dict[str, object] | None = None, n_ir: int = FIRMWARE_IR) -> None:
        self.path = Path(path)
        self.n_ir = n_ir
        if not self.path.parent.exists():
            raise RecordingError(f"{self.path}: folder {self.path.parent} does not exist")
        self.meta: dict[str, object] = {
            "format": FORMAT, "version": VERSION, "source": source, "software": _software_version(),
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "sample_period": sample_period, "columns": columns(n_ir), "units": UNITS,
            "robot": robot or {}, "world": world, "rows": None, "complete": False, **(extra or {}),
        }
        self._write_sidecar()
        with self._writing():
            self._file = open(self.path, "w", newline="", encoding="ascii")
            self._file.write(",".join(columns(n_ir)) + "\n")
            self._file.flush()
        self.rows = 0
        self._last_tick: int | None = None  # TELEMETRY clock, for telemetry()
        self._t_ms = 0

    @contextlib.contextmanager
    def _writing(self) -> Iterator[None]:
        """A disk that fills up during a run is the recording's error, said in one line."""
        try:
            yield
        except OSError as exc:
            raise RecordingError(f"{self.path}: could not write the recording ({exc.strerror or exc})") from None

    def _write_sidecar(self) -> None:
        with self._writing():
            sidecar_path(self.path).write_text(json.dumps(self.meta, indent=1, default=str) + "\n")

    def row(self, t: float, cmd: tuple[float, float], enc: tuple[int, int], ir_on: list[int] | tuple[int, ...],
            ir_amb: list[int] | tuple[int, ...] | None, vbat: float | None,
            pose: tuple[float, float, float] | None = None, *, emitter_pct: float | None = None,
            firmware: tuple[int, float, float, float, float, float] | None = None) -> None:
        """One control cycle.  firmware: (mode, sp_l, sp_r, odo_x, odo_y, odo_phi) in SI units, if known;
        ir_amb and vbat None: not recorded (empty cells)."""
        if len(ir_on) != self.n_ir or (ir_amb is not None and len(ir_amb) != self.n_ir):
            raise RecordingError(f"{self.path}: a row of {len(ir_on)} IR readings for a recording of {self.n_ir}")
        cells = [repr(float(t)), repr(float(cmd[0])), repr(float(cmd[1])), str(int(enc[0])), str(int(enc[1]))]
        cells += [str(int(v)) for v in ir_on]
        cells += [""] * self.n_ir if ir_amb is None else [str(int(v)) for v in ir_amb]
        cells.append("" if vbat is None else repr(float(vbat)))
        cells.append("" if emitter_pct is None else repr(float(emitter_pct)))
        if firmware is None:
            cells += [""] * len(FIRMWARE_VIEW)
        else:
            cells += [str(int(firmware[0]))] + [repr(float(v)) for v in firmware[1:]]
        cells += [repr(float(v)) for v in pose] if pose is not None else ["", "", ""]
        with self._writing():
            self._file.write(",".join(cells) + "\n")
            self._file.flush()
        self.rows += 1

    def telemetry(self, f: dict[str, object], *, t: float | None = None,
                  pose: tuple[float, float, float] | None = None, emitter_pct: float | None = None,
                  cmd: tuple[float, float] | None = None) -> bool:
        """One TELEMETRY frame's fields as a row; False if it repeats the tick before (the same cycle twice).

        t: the time of the row (default: the robot's clock, unwrapped, from its first frame; after a clock
        reset, one firmware period after the row before, the reset's row kept in the sidecar's clock_resets).
        emitter_pct: the emitter power truly in force for the on-reading (a simulator knows it), instead of
        the firmware's report.  cmd: the commands as they reached the robot's drive, in its unit (a simulator
        knows them; docs/recordings.md "The drive block"), instead of the firmware's current references in A.
        Fields an older firmware does not send (emitter_pct, set-points, odometry) are left empty.
        """
        tick = int(f["tick_ms"])  # type: ignore[call-overload]
        if self._last_tick is not None:
            step = (tick - self._last_tick) & TICK_MASK
            if step == 0:
                return False
            if step > _UNWRAP_LIMIT:  # the board restarted: keep recording (tests/test_recordings.py)
                step = DEFAULT_CYCLE_MS
                self._clock_reset()
            self._t_ms += step
        self._last_tick = tick
        firmware = None
        if "odo_heading" in f:
            firmware = (int(f["mode"]), int(f["sp_l"]) / 1000.0, int(f["sp_r"]) / 1000.0,  # type: ignore[call-overload]
                        int(f["odo_x"]) / 1e6, int(f["odo_y"]) / 1e6,  # type: ignore[call-overload]
                        _heading_rad(int(f["odo_heading"])))  # type: ignore[call-overload]
        emitter = f.get("emitter_pct") if emitter_pct is None else emitter_pct
        if cmd is None:
            cmd = (int(f["i_ref_l_ma"]) / 1000.0, int(f["i_ref_r_ma"]) / 1000.0)  # type: ignore[call-overload]
        self.row(self._t_ms / 1000.0 if t is None else t, cmd,
                 (int(f["enc_l"]), int(f["enc_r"])), list(f["ir_on"]), list(f["ir_amb"]),  # type: ignore[call-overload]
                 int(f["vbat_mv"]) / 1000.0, pose,  # type: ignore[call-overload]
                 emitter_pct=None if emitter is None else float(emitter),  # type: ignore[arg-type]
                 firmware=firmware)
        return True

    def _clock_reset(self) -> None:
        """Say in the sidecar, at once, that the robot's clock went back before the next row: its encoders and
        odometry count again from 0 there, which loading's checks refuse to replay across (checks.py)."""
        resets = self.meta.setdefault("clock_resets", [])
        assert isinstance(resets, list)
        resets.append(self.rows)
        self._write_sidecar()

    def close(self) -> None:
        if self._file.closed:
            return
        with self._writing():
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
    cmd: np.ndarray  # (n, 2) in the drive's unit (sidecar "drive"; A for a current drive)
    enc: np.ndarray  # (n, 2) ticks, int64
    ir_on: np.ndarray  # (n, S) counts, int64; S = 0..MAX_IR sensors (the firmware's ring: 8)
    ir_amb: np.ndarray  # (n, S) counts, int64; zeros where not recorded (ambient_recorded False)
    vbat: np.ndarray  # (n,) V; NaN where not recorded (battery_recorded False)
    pose: np.ndarray | None  # (n, 3) x, y, phi, or None without a tracker; NaN rows where it lost the robot
    meta: dict[str, object] = field(default_factory=dict)
    path: Path | None = None
    emitter: np.ndarray | None = None  # (n,) % pulse width of each row's on-reading, None if not recorded
    firmware: np.ndarray | None = None  # (n, 6) mode, sp_l, sp_r, odo_x, odo_y, odo_phi; None if not recorded
    notes: list[Any] = field(default_factory=list)  # checks.Note: what loading's checks found and mended
    ambient_recorded: bool = True

    def __len__(self) -> int:
        return len(self.t)

    @property
    def sample_period(self) -> float:
        return float(self.meta.get("sample_period") or (np.median(np.diff(self.t)) if len(self.t) > 1 else 0.0))

    @property
    def source(self) -> str:
        return str(self.meta.get("source", "robot"))

    @property
    def n_ir(self) -> int:
        return int(self.ir_on.shape[1])

    @property
    def drive(self) -> str:
        """What cmd_l, cmd_r hold: the sidecar's drive block's kind (params.DRIVES; current without one)."""
        block = self.meta.get("drive")
        return str(block["kind"]) if isinstance(block, dict) else "current"

    @property
    def bench(self) -> bool:
        """Recorded on a bench: the wheels off the floor, the body held (docs/recordings.md)."""
        return self.meta.get("bench") is True

    @property
    def battery_recorded(self) -> bool:
        return bool(len(self.vbat)) and bool(np.isfinite(self.vbat).all())

    @property
    def pose_rows(self) -> np.ndarray:
        """(n,) bool: the rows with a tracker pose (_posed)."""
        if self.pose is None:
            return np.zeros(len(self.t), dtype=bool)
        return _posed(self.pose)

    def tracked(self, k: int) -> bool:
        """Whether row k has a tracker pose: pose_rows[k], without casting every row."""
        return self.pose is not None and bool(_posed(self.pose[k]))


def _posed(pose: np.ndarray) -> np.ndarray:
    """Rows of x, y, heading (..., 3) that hold a tracker pose: all three finite."""
    return np.isfinite(pose).all(axis=-1)


def load_recording(path: str | os.PathLike[str], *, require_sidecar: bool = True,
                   ordered_times: bool = True) -> Recording:
    """ordered_times=False lets times repeat or go back, for checks.check_recording to name or mend."""
    path = Path(path)
    meta = _load_sidecar(path, require_sidecar)
    lines = _read_lines(path)
    columns = _check_header(path, lines[0].split(","))
    robot = meta.get("robot") if isinstance(meta.get("robot"), dict) else {}
    adc_max = (1 << int(robot["adc_bits"])) - 1 if "adc_bits" in robot else None  # type: ignore[index,operator,call-overload]
    data, present = _parse_rows(path, lines[1:], columns, adc_max, bool(meta.get("tracker_gaps")),
                                ordered_times)
    n = len(data)
    if meta.get("rows") is not None and meta.get("rows") != n:
        raise RecordingError(f"{path}: the sidecar says {meta['rows']} rows, the file holds {n}")
    col = {name: k for k, name in enumerate(columns)}
    ir_on, ir_amb = ir_columns(sum(c.startswith("ir_on_") for c in columns))

    def group(names: tuple[str, ...] | list[str], dtype: type = float) -> np.ndarray:
        return data[:, [col[c] for c in names]].astype(dtype)

    return Recording(
        t=data[:, 0].copy(), cmd=group(["cmd_l", "cmd_r"]), enc=group(["enc_l", "enc_r"], np.int64),
        ir_on=group(ir_on, np.int64),
        ir_amb=group(ir_amb, np.int64) if present.get(ir_amb, True) else np.zeros((n, len(ir_amb)), np.int64),
        vbat=data[:, col["vbat"]].copy(),
        pose=group(POSE) if present[POSE] else None, meta=meta, path=path,
        emitter=data[:, col["emitter_pct"]].copy() if present.get(("emitter_pct",)) else None,
        firmware=group(FIRMWARE_VIEW) if present.get(FIRMWARE_VIEW) else None,
        ambient_recorded=present.get(ir_amb, True),
    )


def _read_lines(path: Path) -> list[str]:
    try:
        text = path.read_text(encoding="ascii")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror}") from exc
    except UnicodeDecodeError:
        raise RecordingError(f"{path}: not a recording (not ASCII text)") from None
    if not text:
        raise RecordingError(f"{path}: empty file (no header)")
    lines = text.split("\n")
    if lines[-1] != "":
        raise RecordingError(f"{path}:{len(lines)}: last line is cut short (the recorder stopped mid-write); "
                             f"the {len(lines) - 2} rows before it are complete")
    lines.pop()
    return lines


def _check_header(path: Path, header: list[str]) -> list[str]:
    """The header of a version-2 recording of any number of IR sensors, or of a version-1 one of eight."""
    n_ir = sum(c.startswith("ir_on_") for c in header)
    expected = columns(n_ir) if n_ir <= MAX_IR else COLUMNS
    if header in (expected, COLUMNS_V1):
        return header
    missing = [c for c in expected if c not in header]
    extra = [c for c in header if c not in expected]
    detail = []
    if missing:
        detail.append("missing " + ", ".join(missing))
    if extra:
        detail.append("unexpected " + ", ".join(extra))
    if n_ir > MAX_IR:
        detail.append(f"{n_ir} IR sensors, at most {MAX_IR}")
    if not detail:
        detail.append("columns out of order")
    raise RecordingError(f"{path}:1: header is not the recording header ({'; '.join(detail)}); "
                         f"expected: {','.join(expected)}")


def _optional_groups(columns: list[str]) -> list[tuple[tuple[str, ...], list[int]]]:
    """The groups that may be empty, with their column indices: the fixed ones and the ambient readings."""
    names = [g for g in _OPTIONAL_GROUPS if g[0] in columns]
    ambient = tuple(c for c in columns if c.startswith("ir_amb_"))
    if ambient:
        names.append(ambient)
    return [(g, [columns.index(c) for c in g]) for g in names]


def _group_label(names: tuple[str, ...]) -> str:
    return _GROUP_LABELS.get(names) or "the ambient IR readings (ir_amb_*)"


def _parse_rows(path: Path, lines: list[str], columns: list[str], adc_max: int | None,
                tracker_gaps: bool = False, ordered_times: bool = True) -> tuple[np.ndarray, dict[tuple[str, ...], bool]]:
    """Every cell checked; optional groups all-or-nothing in a row and alike in every row (the pose may
    differ from row to row where tracker_gaps)."""
    data = np.zeros((len(lines), len(columns)))
    groups = _optional_groups(columns)
    present: dict[tuple[str, ...], bool] = {}
    for row_index, cells in enumerate(csv.reader(io.StringIO("\n".join(lines)))):
        lineno = row_index + 2
        if len(cells) != len(columns):
            raise RecordingError(f"{path}:{lineno}: {len(cells)} cells, expected {len(columns)}")
        empty_cols: set[int] = set()
        for names, idx in groups:
            empty = [cells[k] == "" for k in idx]
            if any(empty) and not all(empty):
                raise RecordingError(f"{path}:{lineno}: {', '.join(names)} must be all present or all empty")
            here = not all(empty)
            if tracker_gaps and names == POSE:
                present[names] = present.get(names, False) or here
            elif present.setdefault(names, here) != here:
                raise RecordingError(f"{path}:{lineno}: {_group_label(names)} is {'present' if here else 'missing'} "
                                     f"here but not in the rows before")
            if not here:
                empty_cols.update(idx)
        for k, (name, cell) in enumerate(zip(columns, cells)):
            data[row_index, k] = math.nan if k in empty_cols else _cell(path, lineno, name, cell, adc_max)
        if ordered_times and row_index and data[row_index, 0] <= data[row_index - 1, 0]:
            raise RecordingError(f"{path}:{lineno}: column 't': {cells[0]} does not increase "
                                 f"(previous row: {data[row_index - 1, 0]!r})")
    for names, _idx in groups:
        present.setdefault(names, False)
    return data, present


def _cell(path: Path, lineno: int, name: str, cell: str, adc_max: int | None) -> float:
    integer = name in _INT_COLUMNS or name.startswith("ir_")
    try:
        value = int(cell) if integer else float(cell)
    except ValueError:
        kind = "an integer" if integer else "a number"
        raise RecordingError(f"{path}:{lineno}: column '{name}': {cell!r} is not {kind}") from None
    if not math.isfinite(value):
        raise RecordingError(f"{path}:{lineno}: column '{name}': {cell!r} is not finite")
    if name.startswith("ir_") and (value < 0 or (adc_max is not None and value > adc_max)):
        raise RecordingError(f"{path}:{lineno}: column '{name}': {value} is outside the ADC range "
                             f"0..{adc_max if adc_max is not None else '?'}")
    return value


def _load_sidecar(path: Path, required: bool) -> dict[str, object]:
    side = sidecar_path(path)
    if not side.exists():
        if required:
            raise RecordingError(f"{side}: the sidecar of {path.name} is missing (it holds the robot parameters, "
                                 f"the world and the sample period)")
        return {}
    meta = read_json(side, "recording sidecar", RecordingError)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise RecordingError(f"{side}: not a twinbot recording sidecar (format must be '{FORMAT}')")
    if meta.get("version") not in READABLE_VERSIONS:
        raise RecordingError(f"{side}: recording version {meta.get('version')!r}, this twinbot reads "
                             f"{' and '.join(map(str, READABLE_VERSIONS))}")
    period = meta.get("sample_period")
    if not isinstance(period, (int, float)) or period <= 0:
        raise RecordingError(f"{side}: 'sample_period' must be a positive number of seconds, got {period!r}")
    why = drive_refusal(meta)
    if why:
        raise RecordingError(f"{side}: {why}")
    return meta


def drive_refusal(meta: dict[str, object]) -> str | None:
    """Why the sidecar's "drive" block and "bench" flag are refused, or None (docs/recordings.md)."""
    if "bench" in meta and not isinstance(meta["bench"], bool):
        return f"'bench' must be true or false, got {meta['bench']!r}"
    block = meta.get("drive", {"kind": "current"})  # none: every recording before drives had a name
    if not isinstance(block, dict) or block.get("kind") not in DRIVES:
        return f"the drive block must be an object whose 'kind' is one of {', '.join(DRIVES)}, got {block!r}"
    kind = block["kind"]
    if block.get("unit", DRIVE_UNITS[kind]) != DRIVE_UNITS[kind]:
        return f"the drive block's unit must be {DRIVE_UNITS[kind]!r} for a {kind} drive, got {block['unit']!r}"
    robot = meta.get("robot")
    said = robot.get("drive", "current") if isinstance(robot, dict) else kind
    if said != kind:
        return f"the robot's parameters say drive {said!r}, the drive block says {kind!r}"
    return None
