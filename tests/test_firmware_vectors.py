"""Firmware golden vectors (tests/data/firmware_golden.jsonl): the same bits on every port.

The file holds the exact outputs of the integer control path (fuzzy
controller, IR loop, odometry, wheel PI) for 12,500 input sequences,
generated on CPython by tests/data/make_firmware_vectors.py.  Here: the file is
what the generator writes now (so a firmware change that moves any output
fails until the file is regenerated on purpose), CPython and the real
MicroPython reproduce every case, a wrong value is caught and named, and the
vectors cover every rule set, averaging method and odometry method.
"""
from __future__ import annotations

import functools
import importlib.util
import json
import re
from pathlib import Path

import pytest

from firmware import fuzzy, ir, odometry
from tests.data import make_firmware_vectors as gen
from host_sim.board.micropython_runner import run_micropython

HERE = Path(__file__).resolve().parent
GOLDEN = HERE / "data" / "firmware_golden.jsonl"
CHECKER = HERE / "mp" / "firmware_vectors_check.py"
KINDS = ("fz", "ir", "od", "wh")
OK_LINE = re.compile(r"firmware vectors: (\d+) cases ok \(fz (\d+), ir (\d+), od (\d+), wh (\d+)\)\n")


@functools.lru_cache(maxsize=1)
def load() -> tuple[dict, dict[str, list[list]]]:
    """(header, cases by kind) of the checked-in file."""
    lines = GOLDEN.read_text(encoding="ascii").splitlines()
    by_kind: dict[str, list[list]] = {k: [] for k in KINDS}
    for line in lines[1:]:
        case = json.loads(line)
        by_kind[case[0]].append(case)
    return json.loads(lines[0]), by_kind


@functools.lru_cache(maxsize=1)
def checker_module():
    spec = importlib.util.spec_from_file_location("firmware_vectors_check", CHECKER)
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_file_is_what_the_generator_writes() -> None:
    """The checked-in file equals the generator's output now: if a firmware output changes, this
    fails until `python -m tests.data.make_firmware_vectors` is run on purpose."""
    text = GOLDEN.read_text(encoding="ascii")
    fresh = gen.render(*gen.build())
    if text != fresh:
        old, new = text.splitlines(), fresh.splitlines()
        diff = next((i for i, (a, b) in enumerate(zip(old, new)) if a != b), min(len(old), len(new)))
        pytest.fail("tests/data/firmware_golden.jsonl is stale: line {} differs ({} vs {} lines)\n"
                    "file: {}\nnow:  {}".format(diff + 1, len(old), len(new),
                                                old[diff][:300] if diff < len(old) else "<none>",
                                                new[diff][:300] if diff < len(new) else "<none>"))


def test_counts() -> None:
    """At least 10,000 input sequences in all, as many as the header says, each kind's minimum."""
    header, by_kind = load()
    counts = {k: len(v) for k, v in by_kind.items()}
    assert counts == header["counts"]
    assert sum(counts.values()) == header["total"] >= 10000
    assert counts["fz"] >= 10000 and counts["ir"] >= 1000 and counts["od"] >= 1000 and counts["wh"] >= 500


def test_cpython_reproduces_every_case() -> None:
    """The MicroPython checker's own code, run on CPython, reproduces every case."""
    counts, total = checker_module().check_file(str(GOLDEN))
    assert counts == load()[0]["counts"] and total >= 10000


def test_micropython_reproduces_every_case() -> None:
    """The real MicroPython reproduces every case bit for bit, reading the file a line at a
    time within a 512 KB heap."""
    header = load()[0]
    r = run_micropython(CHECKER, str(GOLDEN), heapsize="512k", timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    m = OK_LINE.fullmatch(r.stdout)
    assert m, r.stdout
    total, *per_kind = (int(g) for g in m.groups())
    assert total == header["total"] >= 10000
    assert dict(zip(KINDS, per_kind)) == header["counts"]


def _tamper(case: list) -> list:
    """A copy of case with one expected output off by one."""
    c = json.loads(json.dumps(case))
    kind = c[0]
    if kind == "fz":
        c[3][5] += 1
    elif kind == "ir":
        c[5][-1][9] += 1  # last cycle, value of S2
    elif kind == "od":
        c[6][4][-1] += 1  # EXACT method, final heading
    else:
        c[5][-1][5] += 1  # last step, acc
    return c


@pytest.mark.parametrize("kind", KINDS)
def test_checker_detects_mismatch(kind: str, tmp_path: Path) -> None:
    """One expected value off by one: MicroPython exits 1 naming the line, kind and case; CPython
    raises the same Mismatch."""
    header, by_kind = load()
    good = by_kind[kind][3]
    bad = tmp_path / "bad.jsonl"
    lines = [json.dumps(header), json.dumps(good), json.dumps(_tamper(good))]
    bad.write_text("\n".join(lines) + "\n")
    r = run_micropython(CHECKER, str(bad), heapsize="512k", timeout=60)
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stdout.startswith("firmware vectors: FAIL line 3 ({} case 1): ".format(kind)), r.stdout
    assert "case: [" in r.stdout
    with pytest.raises(checker_module().Mismatch, match=r"line 3 \({} case 1\)".format(kind)):
        checker_module().check_file(str(bad))


def test_replay_hals_agree() -> None:
    """The generator's test HAL and the checker's behave the same."""
    a, b = gen.ReplayHal(), checker_module().ReplayHal()
    outs = []
    for hal in (a, b):
        hal.ambient, hal.on = list(range(8)), list(range(100, 108))
        got: list[list[int]] = []
        for pct in (0, 60, 0, 1, 100):
            hal.set_emitters(pct)
            out = [-1] * 8
            hal.read_ir(out)
            got.append(out)
        outs.append(got)
    assert outs[0] == outs[1]
    assert outs[0][0] == list(range(8)) and outs[0][1] == list(range(100, 108))


def test_fuzzy_coverage() -> None:
    """Both rule sets (which disagree on many vectors), max_speed 0..1000 with the ends, all-zero,
    saturated, ramp-end and single-obstacle vectors on every sensor."""
    header, by_kind = load()
    cases = by_kind["fz"]
    speeds = {c[2] for c in cases}
    assert {0, 1, 1000, header["fuzzy_speed"]} <= speeds and len(speeds) > 900
    differ = sum(c[3][0:2] != c[3][2:4] for c in cases)
    assert 3000 < differ < len(cases)
    readings = [c[1] for c in cases]
    assert [0] * 8 in readings and [ir.ADC_MAX] * 8 in readings
    assert sum(ir.ADC_MAX in r for r in readings) > 500
    for v in (fuzzy.NEAR_LO - 1, fuzzy.NEAR_LO, fuzzy.NEAR_LO + 1, fuzzy.NEAR_HI - 1, fuzzy.NEAR_HI,
              fuzzy.NEAR_HI + 1):
        assert sum(r.count(v) for r in readings) > 100
    for s in range(8):
        assert any(r[s] >= fuzzy.NEAR_HI and sum(r) == r[s] for r in readings)
    # Sanity, not a snapshot: no obstacle -> "go ahead" (55 % of max_speed) on both wheels.
    zero = next(c for c in cases if c[1] == [0] * 8)
    assert zero[3][:4] == [110, 110, 110, 110]


def test_ir_coverage() -> None:
    """Every averaging method (250 sequences each), every window of the moving average and the
    exponential filter, 5..20 cycles, power 0 and 100, saturation, 'on' below the ambient."""
    by_kind = load()[1]
    cases = by_kind["ir"]
    for method in (ir.AVG_NONE, ir.AVG_MOVING, ir.AVG_EXPONENTIAL, ir.AVG_MEDIAN3):
        mine = [c for c in cases if c[2] == method]
        assert len(mine) >= 250
        if method in (ir.AVG_MOVING, ir.AVG_EXPONENTIAL):
            assert {c[3] for c in mine} == set(range(1, ir.MAX_WINDOW + 1))
        if method != ir.AVG_NONE:  # the averaging does something
            assert any(e[:8] != e[8:16] for c in mine for e in c[5])
    assert {len(c[4]) for c in cases} == set(range(5, 21))
    assert {0, 100} <= {c[1] for c in cases}
    sat = [e[16] for c in cases for e in c[5]]
    assert 500 < sum(sat) < len(sat) - 500
    below = sum(cyc[8 + s] < cyc[s] for c in cases for cyc in c[4] for s in range(8))
    assert below > 1000


def test_odometry_coverage() -> None:
    """Every sequence is run with all three methods, by step() and by update(), over the geometry
    ranges; straight lines, rotations on the spot and multi-turn steps are there, and they behave."""
    header, by_kind = load()
    cases = by_kind["od"]
    every = header["odometry_every"]
    assert all(len(c[6]) == 2 + len((odometry.EULER, odometry.MIDPOINT, odometry.EXACT)) for c in cases)
    assert {len(c[5]) // 2 for c in cases} == set(range(10, 51))
    assert 20000 <= min(c[1] for c in cases) < 25000 and 75000 < max(c[1] for c in cases) <= 80000
    assert 50000 <= min(c[2] for c in cases) < 60000 and 190000 < max(c[2] for c in cases) <= 200000
    assert 100 <= min(c[3] for c in cases) < 200 and 4900 < max(c[3] for c in cases) <= 5000
    assert 200 < sum(c[4] is not None for c in cases) < 800
    assert all(-2 ** 29 <= v < 2 ** 29 for c in cases if c[4] for v in c[4])  # the HALs' count range
    straight = rotation = big_turn = 0
    for c in cases:
        steps, (q8, hpt, *poses) = c[5], c[6]
        dls, drs = steps[0::2], steps[1::2]
        n_poses = len(poses[0]) // 3
        assert n_poses == (len(dls) - 1) // every + 1
        if any(dls) and dls == drs:  # straight: heading and y stay 0, the methods agree
            straight += 1
            assert poses[0] == poses[1] == poses[2]
            assert all(p[3 * k + 1] == 0 and p[3 * k + 2] == 0 for p in poses for k in range(n_poses))
        if any(dls) and dls == [-d for d in drs]:  # on the spot: x, y stay 0
            rotation += 1
            assert all(p[3 * k] == 0 and p[3 * k + 1] == 0 for p in poses for k in range(n_poses))
            assert poses[2][-1] == (sum(drs) - sum(dls)) * hpt % odometry.HEADING_TURN
        if any(abs(r - l) * hpt > odometry.HEADING_TURN for l, r in zip(dls, drs)):
            big_turn += 1
    assert straight > 50 and rotation > 50 and big_turn > 50


def test_wheel_coverage() -> None:
    """Gains and limits from 0 to their maxima, resets, dt 0, both saturated and linear PI steps,
    encoder counts across the HALs' wrap at +-2**29 (never beyond it)."""
    cases = load()[1]["wh"]
    assert min(c[2] for c in cases) == 0 and max(c[2] for c in cases) == 100000
    assert min(c[3] for c in cases) == 0 and max(c[3] for c in cases) == 100000
    assert {0, 3000} <= {c[4] for c in cases}
    counts = [s[0] for c in cases for s in c[5]]
    assert -2 ** 29 <= min(counts) and max(counts) < 2 ** 29
    assert any(a > 2 ** 28 and b < -2 ** 28 for c in cases for a, b in zip([s[0] for s in c[5]], [s[0] for s in c[5][1:]]))
    steps = [s for c in cases for s in c[5]]
    assert sum(s[2] is None for s in steps) > 200
    assert sum(s[1] == 0 for s in steps) >= len(cases)
    clamped = sum(s[6] for s in steps)
    assert 1000 < clamped < len(steps) - 1000
    assert sum(s[5] != 0 for s in steps) > 1000
