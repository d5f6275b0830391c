"""The test block: a final part of the recording, or a second recording, that no split, selection, tie or
stopping rule sees; the fitted twin and every judgement of the verdict are reported on it.

split_test_block cuts a recording into the part the diagnosis fits and the test block; docs/diagnosis.md,
"The test block".
"""
from __future__ import annotations

import dataclasses
import math

from host_sim.diagnosis.windows import DEFAULT_SECONDS, OFFSET_S, grid_starts
from host_sim.recordings.recording import Recording

TEST_FRACTION = 0.25  # of the 1 s windows, the last ones: the test block
MIN_TEST_WINDOWS = 6  # 1 s windows at least: fewer, and a trend or a whiteness test rests on too few blocks
MIN_FIT_WINDOWS = 6  # 1 s windows left to fit on (report.MIN_WINDOWS): the held-out split needs a few of each


class TestBlockError(ValueError):
    """Too short to leave a test block and enough windows to fit; the message says how long it must be."""


def slice_recording(rec: Recording, first: int, stop: int) -> Recording:
    """Rows first .. stop - 1 of a recording, times kept (a span said in seconds is the recording's)."""
    cut = slice(first, stop)
    return dataclasses.replace(rec, t=rec.t[cut], cmd=rec.cmd[cut], enc=rec.enc[cut], ir_on=rec.ir_on[cut],
                               ir_amb=rec.ir_amb[cut], vbat=rec.vbat[cut],
                               pose=None if rec.pose is None else rec.pose[cut],
                               emitter=None if rec.emitter is None else rec.emitter[cut],
                               firmware=None if rec.firmware is None else rec.firmware[cut])


def window_count(rec: Recording, seconds: float = DEFAULT_SECONDS[0]) -> int:
    """How many back-to-back windows of `seconds` windows.make_windows' grid lays over the recording, the
    test block's split counted on (those it leaves out, over a late or lost row, counted too)."""
    return len(grid_starts(rec, seconds)[0])


def shortest_seconds(fraction: float, seconds: float = DEFAULT_SECONDS[0]) -> float:
    """The shortest recording that leaves MIN_FIT_WINDOWS to fit and a test block of MIN_TEST_WINDOWS (or
    `fraction` of all, if more)."""
    total = MIN_FIT_WINDOWS + MIN_TEST_WINDOWS
    while total - max(MIN_TEST_WINDOWS, math.ceil(fraction * total)) < MIN_FIT_WINDOWS:
        total += 1
    return OFFSET_S + total * seconds + seconds / 25


def split_test_block(rec: Recording, fraction: float = TEST_FRACTION,
                     seconds: float = DEFAULT_SECONDS[0]) -> tuple[Recording, Recording]:
    """(the part fitted, the test block): the last `fraction` of the 1 s windows, MIN_TEST_WINDOWS at least.

    The test block starts OFFSET_S before its first window, so its own windows are the recording's last
    ones, row for row; the rows before that window are its lead-in (the recorded state a twin starts
    from), never judged.  The fitted part ends on the row after its last window, which closes that
    window's period (tests/test_verdict.py::test_the_test_block_is_the_last_quarter_and_nothing_else_sees_it)."""
    if not 0.0 < fraction < 1.0:
        raise TestBlockError(f"the test fraction must lie between 0 and 1, not {fraction:g}")
    start, _rows, offset = grid_starts(rec, seconds)
    n_windows = len(start)  # window_count's
    n_test = max(MIN_TEST_WINDOWS, math.ceil(fraction * n_windows))
    if n_windows - n_test < MIN_FIT_WINDOWS:
        raise TestBlockError(f"the recording lasts {len(rec) * rec.sample_period:.1f} s: too short to diagnose and "
                             f"keep a test block (at least {shortest_seconds(fraction, seconds):.0f} s; "
                             f"60-90 s is better)")
    first_test = int(start[n_windows - n_test])  # the test block's first window's first row
    fitted = slice_recording(rec, 0, first_test + 1)
    test = slice_recording(rec, first_test - offset, len(rec))
    assert window_count(test, seconds) == n_test and window_count(fitted, seconds) == n_windows - n_test
    return fitted, test


def check_test_recording(test: Recording, seconds: float = DEFAULT_SECONDS[0]) -> None:
    """A second recording given as the test block must hold MIN_TEST_WINDOWS windows."""
    if window_count(test, seconds) < MIN_TEST_WINDOWS:
        raise TestBlockError(f"the test recording lasts {len(test) * test.sample_period:.1f} s: too short for a test "
                             f"block (at least {OFFSET_S + MIN_TEST_WINDOWS * seconds + seconds / 25:.0f} s)")
