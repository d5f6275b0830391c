"""What loading checks (host_sim/recordings/checks.py, docs/recordings.md "What loading checks").

A clean recording made by the twin (`twinbot sim --excite --record`), then corrupted in the test as a real
robot's log goes wrong: rows lost or repeated, the clock reset or wrapped, an encoder wrapped at 2^16, the
commands in mA, the tracker in mm, an encoder's sign flipped.  Each gives its note, or its one-line refusal
with exit status 2, through the real command line; the clean one gives none.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import pytest

from host_sim.physics.params import DEFAULT
from host_sim.recordings.checks import RecordingCheckError, check_recording, speed_memory, top_speed
from host_sim.recordings.recording import load_recording
from tests.helpers import run_twinbot

DATA = Path(__file__).parent / "data"
Rows = list[list[str]]


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("checks") / "clean.csv"
    r = run_twinbot("sim", "--excite", "--world", "arena", "--duration", "20", "--seed", "3", "--record", str(path))
    assert r.returncode == 0, r.stderr
    return path


def corrupt(clean: Path, tmp_path: Path, change: Callable[[list[str], Rows], Rows]) -> Path:
    """A copy of the clean recording with its rows (cells as text) changed; the sidecar's row count follows."""
    header, *lines = clean.read_text().splitlines()
    rows = change(header.split(","), [line.split(",") for line in lines])
    out = tmp_path / "corrupt.csv"
    out.write_text("\n".join([header] + [",".join(row) for row in rows]) + "\n")
    meta = json.loads(Path(str(clean) + ".json").read_text())
    meta["rows"] = len(rows)
    Path(str(out) + ".json").write_text(json.dumps(meta))
    return out


def column(header: list[str], rows: Rows, name: str, f: Callable[[str], str], first: int = 0) -> Rows:
    k = header.index(name)
    for row in rows[first:]:
        row[k] = f(row[k])
    return rows


def refused(path: Path, words: str, command: tuple[str, ...] = ("replay",)) -> str:
    """The one line on stderr, exit status 2, nothing written beside the recording."""
    r = run_twinbot(*command, str(path))
    assert r.returncode == 2, r.stdout + r.stderr
    assert sorted(f.name for f in path.parent.iterdir()) == ["corrupt.csv", "corrupt.csv.json"]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert words in lines[0], lines[0]
    return lines[0]


def noted(path: Path, name: str) -> list[str]:
    r = run_twinbot("replay", str(path))
    assert r.returncode == 0, r.stderr
    notes = [line for line in r.stdout.splitlines() if line.startswith("  note: ")]
    assert notes, r.stdout
    rec = check_recording(load_recording(path, ordered_times=False), DEFAULT)
    assert [n.name for n in rec.notes] == [name], rec.notes
    return notes


def test_the_clean_recording_gives_no_note(clean):
    r = run_twinbot("replay", str(clean))
    assert r.returncode == 0 and "note:" not in r.stdout, r.stdout + r.stderr
    assert check_recording(load_recording(clean), DEFAULT).notes == []


def test_a_board_whose_loop_overran_gives_at_most_a_note_on_its_late_rows():
    """Its rows are 9-248 ms apart where 40 ms is nominal: late, all of them far within the speed's memory."""
    rec = check_recording(load_recording(DATA / "vboard_6busy_46s.csv"), DEFAULT)
    assert [n.name for n in rec.notes] == ["late_rows"] and len(rec) == 1142


def test_the_thresholds_come_from_the_robots_physics():
    """J/c_v of the nominal robot (docs/recordings.md): 0.62 s; its wheels' top speed V/(k_e N): 38.9 rad/s."""
    assert speed_memory(DEFAULT) == pytest.approx(0.622, abs=0.001)
    assert top_speed(DEFAULT) == pytest.approx(38.95, abs=0.01)
    assert speed_memory(DEFAULT.replace(viscous_friction=0.0)) == pytest.approx(3.23, abs=0.01)


def test_lost_rows_are_a_note_with_where_in_the_diagnosis_text_json_and_html(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda _h, rows: rows[:100] + rows[102:300] + rows[301:])
    out = tmp_path / "verdict.json"
    page = tmp_path / "report.html"
    r = run_twinbot("diagnose", str(path), "--quiet", "--workers", "1", "--json", str(out), "--html", str(page),
                    timeout=300)
    assert r.returncode == 0, r.stderr
    assert "recording (late_rows): 2 row(s) late or after missing ones" in r.stdout, r.stdout
    assert "rows 100 (t 4.080 s, 120 ms after), 298 (t 12.040 s, 80 ms after)" in r.stdout
    (item,) = json.loads(out.read_text())["recording_checks"]
    assert item["name"] == "late_rows" and item["rows"] == [100, 298] and item["times"] == [4.08, 12.04]
    assert "recording (late_rows)" in page.read_text()


def test_rows_too_far_apart_for_the_dynamics_are_refused(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda _h, rows: rows[:100] + rows[130:])
    assert "row 100 (t 5.200 s) comes 1240 ms after the row before: too far apart" in refused(path, "J/c_v")


def test_rows_recorded_a_second_apart_are_refused(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda _h, rows: rows[::28])
    refused(path, "rows 1120 ms apart: too far apart for the robot's dynamics")


def test_a_repeated_row_is_dropped_with_a_note(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda _h, rows: rows[:200] + [list(rows[199])] + rows[200:])
    (note,) = noted(path, "repeated_rows")
    assert "row 200 (t 7.960 s): dropped" in note


def test_a_clock_reset_is_refused(clean, tmp_path):
    shift = lambda h, rows: column(h, rows, "t", lambda t: repr(float(t) - 16.0), first=400)  # noqa: E731
    refused(corrupt(clean, tmp_path, shift), "row 400: the clock goes back from 15.960 s to 0.000 s, a reset")


def test_a_restart_the_recorder_saw_is_refused_not_replayed_as_an_encoder_step(clean, tmp_path):
    """The board restarted before row 400: the writer carries its time on and says so in the sidecar; the
    counters start again from 0 there, a step back no wheel turns in one period, nor a wrap."""
    def restart(h: list[str], rows: Rows) -> Rows:
        for name in ("enc_l", "enc_r"):
            zero = int(rows[400][h.index(name)])
            rows = column(h, rows, name, lambda e, zero=zero: str(int(e) - zero), first=400)  # type: ignore[misc]
        return rows

    path = corrupt(clean, tmp_path, restart)
    sidecar = Path(str(path) + ".json")
    sidecar.write_text(json.dumps(json.loads(sidecar.read_text()) | {"clock_resets": [400]}))
    refused(path, "row 400 (t 16.000 s): the robot restarted just before it (its clock was reset", ("diagnose",))
    sidecar.write_text(json.dumps(json.loads(sidecar.read_text()) | {"clock_resets": [400, 100000]}))
    with pytest.raises(RecordingCheckError, match="clock_resets must list row numbers of the recording"):
        check_recording(load_recording(path), DEFAULT)


def test_a_wrapped_clock_is_unwrapped_with_a_note(clean, tmp_path):
    """A raw 16-bit millisecond clock: it goes back by 65.536 s, and one period later it is."""
    wrap = lambda h, rows: column(h, rows, "t", lambda t: repr(float(t) + 65.536 - 16.0), first=0)  # noqa: E731
    path = corrupt(clean, tmp_path, lambda h, rows: column(h, wrap(h, rows), "t",
                                                             lambda t: repr(float(t) - 65.536), first=400))
    (note,) = noted(path, "clock_wrap")
    assert "the clock wraps at row 400" in note


def test_an_encoder_wrapped_at_16_bits_is_unwrapped_with_a_note(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda h, rows: column(h, rows, "enc_l", lambda e: str((int(e) - 500) % 65536)))
    (note,) = noted(path, "encoder_wrap")
    assert "the left encoder (enc_l) wraps at 16 bits at row" in note
    mended = check_recording(load_recording(path), DEFAULT).enc
    moved = mended - load_recording(clean).enc
    assert (moved[:, 0] == -500).all() and (moved[:, 1] == 0).all()  # the counts as they were, from -500


def test_commands_in_ma_are_refused(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda h, rows: column(h, column(h, rows, "cmd_l", lambda c: repr(1000 * float(c))),
                                                           "cmd_r", lambda c: repr(1000 * float(c))))
    assert "times the current limit 0.5 A" in refused(path, "the commands are likely in mA", ("diagnose",))


def test_a_tracker_pose_in_mm_is_refused(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda h, rows: column(h, column(h, rows, "x", lambda c: repr(1000 * float(c))),
                                                           "y", lambda c: repr(1000 * float(c))))
    refused(path, "the pose is likely in mm", ("plot", "recording"))


def test_an_encoder_counting_backwards_is_refused(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda h, rows: column(h, rows, "enc_r", lambda e: str(-int(e))))
    refused(path, "the right wheel turns against its commands")


def test_an_encoder_that_jumps_farther_than_its_wheel_turns_is_refused(clean, tmp_path):
    path = corrupt(clean, tmp_path, lambda h, rows: column(h, rows, "enc_l", lambda e: str(int(e) + 5000), first=300))
    assert "a counter reset or a glitch" in refused(path, "the left encoder jumps")


def test_the_boards_late_rows_are_noted_and_its_diagnosis_stays_a_match():
    r = run_twinbot("diagnose", str(DATA / "vboard_6busy_46s.csv"), "--quiet", "--workers", "1", timeout=300)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].endswith(": match") and lines[1].startswith("  recording (late_rows): 12 row(s) late"), r.stdout
