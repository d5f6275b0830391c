"""Frame logs: every frame a harness saw or sent, one JSON object a line (docs/frame-log.md).

Written as frames arrive, appended and flushed line by line, so a killed process loses
nothing it had received.  The reader decodes every frame's bytes again and checks them
against the logged type, sequence and fields, so a damaged file is never half-read.
"""
from __future__ import annotations

import datetime
import json
import os
from pathlib import Path

from protocol import messages as M
from protocol.framing import FrameDecoder
from host_sim.board.serial_link import Frame

FORMAT = "twinbot-frames"
VERSION = 1


class FrameLogError(ValueError):
    """A frame log is malformed; the message names the file and line."""


class FrameLogWriter:
    """Appends frames to a log; every line is flushed as it is written."""

    def __init__(self, path: str | os.PathLike[str], port: str) -> None:
        self.path = Path(path)
        if self.path.parent and not self.path.parent.exists():
            raise FrameLogError(f"{self.path}: folder {self.path.parent} does not exist")
        try:
            self._file = open(self.path, "a", encoding="utf-8")
        except OSError as exc:
            raise FrameLogError(f"{self.path}: cannot open for appending: {exc.strerror}") from exc
        self._write({
            "kind": "session", "format": FORMAT, "version": VERSION, "port": port,
            "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="milliseconds"),
        })

    def _write(self, record: dict[str, object]) -> None:
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._file.flush()

    def frame(self, frame: Frame) -> None:
        self._write({
            "kind": "frame", "t": round(frame.t, 6), "dir": frame.direction, "type": frame.name,
            "seq": frame.seq, "fields": _jsonable(frame.fields), "frame": frame.raw.hex(),
        })

    def stats(self, t: float, counters: dict[str, int]) -> None:
        self._write({"kind": "stats", "t": round(t, 6), "decoder": counters})

    def close(self) -> None:
        self._file.close()


def _jsonable(fields: dict[str, object]) -> dict[str, object]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in fields.items()}


def read_frame_log(path: str | os.PathLike[str]) -> list[dict[str, object]]:
    """Every record of a frame log, checked; FrameLogError names file:line on any fault."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FrameLogError(f"{path}: cannot read: {exc.strerror}") from exc
    except UnicodeDecodeError as exc:
        raise FrameLogError(f"{path}: not a frame log (not UTF-8 text)") from exc
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    elif lines:
        raise FrameLogError(
            f"{path}:{len(lines)}: last line is cut short (the recorder was stopped mid-write); "
            f"the {len(lines) - 1} lines before it are complete"
        )
    records: list[dict[str, object]] = []
    for lineno, line in enumerate(lines, 1):
        where = f"{path}:{lineno}"
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as exc:
            raise FrameLogError(f"{where}: not valid JSON ({exc.msg} at column {exc.colno})") from exc
        if not isinstance(rec, dict) or "kind" not in rec:
            raise FrameLogError(f"{where}: expected a JSON object with a 'kind'")
        kind = rec["kind"]
        if lineno == 1 and (kind != "session" or rec.get("format") != FORMAT):
            raise FrameLogError(f"{where}: not a twinbot frame log (first line must be a '{FORMAT}' session record)")
        if kind == "session":
            if rec.get("version") != VERSION:
                raise FrameLogError(f"{where}: frame log version {rec.get('version')!r}, this twinbot reads {VERSION}")
        elif kind == "frame":
            _check_frame(rec, where)
        elif kind != "stats":
            raise FrameLogError(f"{where}: unknown record kind {kind!r}")
        records.append(rec)
    return records


def _check_frame(rec: dict[str, object], where: str) -> None:
    for key in ("t", "dir", "type", "seq", "fields", "frame"):
        if key not in rec:
            raise FrameLogError(f"{where}: frame record has no '{key}'")
    if rec["dir"] not in ("rx", "tx"):
        raise FrameLogError(f"{where}: 'dir' must be 'rx' or 'tx', not {rec['dir']!r}")
    try:
        raw = bytes.fromhex(str(rec["frame"]))
    except ValueError as exc:
        raise FrameLogError(f"{where}: 'frame' is not hex") from exc
    dec = FrameDecoder()
    frames = dec.decode_all(raw)
    if len(frames) != 1 or dec.errors:
        raise FrameLogError(f"{where}: 'frame' bytes do not decode to one valid frame (damaged: {dec.stats()})")
    msg_type, seq, payload = frames[0]
    if M.NAMES[msg_type] != rec["type"] or seq != rec["seq"]:
        raise FrameLogError(
            f"{where}: frame bytes hold {M.NAMES[msg_type]} #{seq} but the record says {rec['type']} #{rec['seq']}"
        )
    if _jsonable(M.unpack_payload(msg_type, payload)) != rec["fields"]:
        raise FrameLogError(f"{where}: 'fields' disagree with the frame bytes")
