"""Every subcommand, walked through a table of bad inputs.

The promise: bad input gets one line on stderr naming what is wrong, and exit status 2.
Each row runs the real `twinbot` command and checks exactly that: status 2, one line on
stderr that names the value, no traceback, and nothing written (no output file, no stray
sidecar, no `twinbot-board-*` folder in the temporary directory).  Every bad value must
fail before any heavy work, so the rows run concurrently in a few seconds.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from tests.helpers import REPO

# (id, arguments, text the one line must contain).  In the arguments,
# {case} is the row's own empty-at-start folder (holding `afile` and
# `adir/`), {in} the shared folder of input files made by `inputs()`.
CASES: list[tuple[str, list[str], str]] = [
    # the command itself
    ("no-command", [], "COMMAND missing"),
    ("unknown-command", ["bogus"], "bogus"),
    ("unknown-option", ["sim", "--bogus"], "--bogus"),
    # gui (every row fails before a window opens)
    ("gui-speed-zero", ["gui", "--speed", "0"], "'0'"),
    ("gui-speed-nan", ["gui", "--speed", "nan"], "'nan'"),
    ("gui-speed-huge", ["gui", "--speed", "1e9"], "'1e9'"),
    ("gui-emitter-over", ["gui", "--emitter", "101"], "'101'"),
    ("gui-seed-negative", ["gui", "--seed", "-1"], "'-1'"),
    ("gui-frames-zero", ["gui", "--frames", "0"], "'0'"),
    ("gui-screenshot-format", ["gui", "--frames", "1", "--screenshot", "{case}/x.xyz"], ".xyz"),
    ("gui-screenshot-in-a-file", ["gui", "--frames", "1", "--screenshot", "{case}/afile/x.png"], "afile"),
    ("gui-screenshot-without-frames", ["gui", "--screenshot", "{case}/x.png"], "--frames"),
    ("gui-out-missing", ["gui", "--frames", "1", "--out", "{case}/missing"], "missing"),
    ("gui-world-missing", ["gui", "--frames", "1", "--world", "{case}/nope.json"], "nope.json"),
    ("gui-port-missing", ["gui", "--frames", "1", "--port", "{case}/ttyNOPE"], "ttyNOPE"),
    ("gui-link-floor-negative", ["gui", "--link-floor", "-5"], "'-5'"),
    ("gui-pil-port-missing", ["gui", "--frames", "1", "--pil", "--port", "{case}/ttyNOPE"], "ttyNOPE"),
    ("gui-replay-missing", ["gui", "--frames", "1", "--replay", "{case}/nope.csv"], "nope.csv"),
    ("gui-replay-folder", ["gui", "--frames", "1", "--replay", "{case}/adir"], "adir"),
    ("gui-replay-not-a-recording", ["gui", "--frames", "1", "--replay", "{in}/bad.csv"], "bad.csv"),
    ("gui-replay-garbage", ["gui", "--frames", "1", "--replay", "{in}/garbage.img"], "garbage.img"),
    # sim
    ("sim-duration-nan", ["sim", "--duration", "nan"], "'nan'"),
    ("sim-duration-inf", ["sim", "--duration", "inf"], "'inf'"),
    ("sim-duration-below-a-cycle", ["sim", "--duration", "0.01"], "'0.01'"),
    ("sim-duration-negative", ["sim", "--duration", "-1"], "'-1'"),
    ("sim-duration-huge", ["sim", "--duration", "1e12"], "'1e12'"),
    ("sim-duration-word", ["sim", "--duration", "long"], "'long'"),
    ("sim-seed-negative", ["sim", "--seed", "-1"], "'-1'"),
    ("sim-substeps-zero", ["sim", "--substeps", "0"], "'0'"),
    ("sim-speed-zero", ["sim", "--speed", "0"], "'0'"),
    ("sim-speed-nan", ["sim", "--speed", "nan"], "'nan'"),
    ("sim-speed-inf-realtime", ["sim", "--realtime", "--speed", "inf"], "'inf'"),
    ("sim-speed-word", ["sim", "--speed", "fast"], "'fast'"),
    ("sim-png-format", ["sim", "--png", "{case}/x.xyz"], ".xyz"),
    ("sim-png-no-extension", ["sim", "--png", "{case}/picture"], "no extension"),
    ("sim-png-onto-folder", ["sim", "--png", "{case}/adir"], "adir"),
    ("sim-png-in-a-file", ["sim", "--png", "{case}/afile/x.png"], "afile"),
    ("sim-record-in-a-file", ["sim", "--record", "{case}/afile/run.csv"], "afile"),
    ("sim-record-onto-folder", ["sim", "--record", "{case}/adir"], "adir"),
    ("sim-record-sidecar-folder", ["sim", "--record", "{case}/taken.csv"], "taken.csv.json"),
    ("sim-record-no-folder", ["sim", "--record", "{case}/missing/run.csv"], "missing"),
    ("sim-record-then-bad-world", ["sim", "--record", "{case}/run.csv", "--world", "{in}/huge.json"], "limit"),
    ("sim-record-then-bad-png", ["sim", "--record", "{case}/run.csv", "--png", "{case}/x.xyz"], ".xyz"),
    ("sim-world-huge", ["sim", "--world", "{in}/huge.json"], "1e+09 m"),
    ("sim-world-1000m", ["sim", "--world", "{in}/big.json"], "1000 m"),
    ("sim-world-many-walls", ["sim", "--world", "{in}/walls.json"], "wall segments"),
    ("sim-world-not-utf8", ["sim", "--world", "{in}/latin1.json"], "UTF-8"),
    ("sim-world-lamp-level", ["sim", "--world", "{in}/lamp.json"], "level"),
    ("sim-world-far-wall", ["sim", "--world", "{in}/far.json"], "walls[0]"),
    ("sim-world-missing", ["sim", "--world", "nowhere"], "nowhere"),
    ("sim-params-adc-bits", ["sim", "--params", "{in}/adc64.json"], "adc_bits"),
    ("sim-params-ticks", ["sim", "--params", "{in}/ticks.json"], "ticks_per_rev"),
    ("sim-params-list-item", ["sim", "--params", "{in}/gains.json"], "ir_gain_scale"),
    ("sim-params-not-json", ["sim", "--params", "{in}/bad.json"], "not valid JSON"),
    # demo
    ("demo-duration-zero", ["demo", "--duration", "0", "--out", "{case}/demo"], "'0'"),
    ("demo-duration-negative", ["demo", "--duration", "-1", "--out", "{case}/demo"], "'-1'"),
    ("demo-duration-nan", ["demo", "--duration", "nan", "--out", "{case}/demo"], "'nan'"),
    ("demo-repeat-speed-zero", ["demo", "--repeat-speed", "0", "--out", "{case}/demo"], "'0'"),
    ("demo-repeat-duration-inf", ["demo", "--repeat-duration", "inf", "--out", "{case}/demo"], "'inf'"),
    ("demo-out-a-file", ["demo", "--out", "{case}/afile"], "afile"),
    ("demo-out-under-a-file", ["demo", "--out", "{case}/afile/demo"], "afile"),
    ("demo-world-missing", ["demo", "--world", "nowhere", "--out", "{case}/demo"], "nowhere"),
    # board
    ("board-late-negative", ["board", "--late", "-1"], "'-1'"),
    ("board-jitter-nan", ["board", "--late", "100", "--jitter", "nan"], "'nan'"),
    ("board-hw-port-big", ["board", "--hw-port", "99999"], "'99999'"),
    ("board-hw-port-zero", ["board", "--hw-port", "0"], "'0'"),
    ("board-image-not-littlefs", ["board", "--image", "{in}/garbage.img"], "littlefs"),
    ("board-image-folder", ["board", "--image", "{case}/adir"], "adir"),
    ("board-image-in-a-file", ["board", "--image", "{case}/afile/board.img"], "afile"),
    ("board-flash-kb-small", ["board", "--image", "{case}/new.img", "--flash-kb", "10"], "'10'"),
    ("board-image-and-flash-dir", ["board", "--image", "{case}/new.img", "--flash-dir", "{case}/fd", "--standin"],
     "not both"),
    ("board-flash-dir-a-file", ["board", "--flash-dir", "{case}/afile"], "afile"),
    ("board-log-folder", ["board", "--log", "{case}/adir"], "adir"),
    ("board-world-missing", ["board", "--world", "nowhere", "--flash-dir", "{case}/fd"], "nowhere"),
    # serial
    ("serial-duration-nan", ["serial", "loop://", "--duration", "nan"], "'nan'"),
    ("serial-duration-negative", ["serial", "loop://", "--duration", "-1"], "'-1'"),
    ("serial-duration-zero", ["serial", "loop://", "--duration", "0"], "'0'"),
    ("serial-rate-negative", ["serial", "loop://", "--rate", "-1", "--duration", "1"], "'-1'"),
    ("serial-rate-nan", ["serial", "loop://", "--rate", "nan", "--duration", "1"], "'nan'"),
    ("serial-count-zero", ["serial", "loop://", "--count", "0"], "'0'"),
    ("serial-baud-zero", ["serial", "loop://", "--baud", "0", "--duration", "1"], "'0'"),
    ("serial-command-mode", ["serial", "loop://", "--command", "fly", "1", "2", "--duration", "1"], "'fly'"),
    ("serial-command-speed", ["serial", "loop://", "--command", "host", "1", "99999", "--duration", "1"], "99999"),
    ("serial-param-unknown", ["serial", "loop://", "--param-set", "nosuch=1", "--duration", "1"], "'nosuch'"),
    ("serial-param-range", ["serial", "loop://", "--param-set", "max_speed=99999", "--duration", "1"], "max_speed"),
    ("serial-record-folder", ["serial", "loop://", "--record", "{case}/adir", "--duration", "1"], "adir"),
    ("serial-record-in-a-file", ["serial", "loop://", "--record", "{case}/afile/r.csv", "--duration", "1"], "afile"),
    ("serial-port-missing", ["serial", "/dev/ttyTWINBOT_NONE", "--duration", "1"], "/dev/ttyTWINBOT_NONE"),
    ("serial-port-scheme", ["serial", "bogus://x", "--duration", "1"], "bogus://x"),
    ("serial-restart-with-a-value", ["serial", "loop://", "--restart=yes", "--duration", "1"], "--restart"),
    ("serial-restart-port-missing", ["serial", "/dev/ttyTWINBOT_NONE", "--restart", "--duration", "1"],
     "/dev/ttyTWINBOT_NONE"),
    # flash
    ("flash-no-port", ["flash"], "--port"),
    ("flash-port-missing", ["flash", "--port", "/dev/ttyTWINBOT_NONE"], "/dev/ttyTWINBOT_NONE"),
    ("flash-timeout-nan", ["flash", "--port", "/dev/ttyTWINBOT_NONE", "--timeout", "nan"], "'nan'"),
    # fuzzy
    ("fuzzy-plot-folder", ["fuzzy", "--plot", "{case}/adir"], "adir"),
    ("fuzzy-plot-no-extension", ["fuzzy", "--plot", "{case}/sets"], "no extension"),
    ("fuzzy-eval-negative", ["fuzzy", "--eval", "-5", "99999", "0", "0", "0", "0", "0", "0"], "'-5'"),
    ("fuzzy-eval-too-big", ["fuzzy", "--eval", "0", "99999", "0", "0", "0", "0", "0", "0"], "'99999'"),
    ("fuzzy-eval-too-few", ["fuzzy", "--eval", "0", "1"], "--eval"),
    ("fuzzy-max-speed-big", ["fuzzy", "--max-speed", "100000"], "'100000'"),
    ("fuzzy-max-speed-zero", ["fuzzy", "--max-speed", "0"], "'0'"),
    ("fuzzy-rules-unknown", ["fuzzy", "--rules", "best"], "'best'"),
    # plot
    ("plot-no-figure", ["plot"], "FIGURE"),
    ("plot-sensor-params-bad", ["plot", "sensor", "--params", "{in}/bad.json", "--out", "{case}/figs"],
     "not valid JSON"),
    ("plot-sensor-params-range", ["plot", "sensor", "--params", "{in}/adc64.json", "--out", "{case}/figs"],
     "adc_bits"),
    ("plot-sensor-params-missing", ["plot", "sensor", "--params", "{case}/none.json", "--out", "{case}/figs"],
     "none.json"),
    ("plot-sensor-out-a-file", ["plot", "sensor", "--out", "{case}/afile"], "afile"),
    ("plot-worlds-out-under-a-file", ["plot", "worlds", "--out", "{case}/afile/figs"], "afile"),
    ("plot-recording-missing", ["plot", "recording", "{case}/none.csv"], "none.csv"),
    ("plot-recording-bad", ["plot", "recording", "{in}/bad.csv"], "bad.csv"),
    ("plot-recording-png-format", ["plot", "recording", "{in}/run.csv", "--png", "{case}/x.xyz"], ".xyz"),
    ("plot-recording-world-bad", ["plot", "recording", "{in}/run.csv", "--world", "{in}/latin1.json",
                                  "--png", "{case}/r.png"], "UTF-8"),
    # import
    ("import-log-missing", ["import", "{case}/none.csv", "--map", "{in}/map.json", "--robot", "{in}/robot.json",
                            "--out", "{case}/r.csv"], "none.csv"),
    ("import-map-not-json", ["import", "{in}/log.csv", "--map", "{in}/bad.json", "--robot", "{in}/robot.json",
                             "--out", "{case}/r.csv"], "not valid JSON"),
    ("import-map-kind", ["import", "{in}/log.csv", "--map", "{in}/map_kind.json", "--robot", "{in}/robot.json",
                         "--out", "{case}/r.csv"], "command.kind"),
    ("import-map-column", ["import", "{in}/log.csv", "--map", "{in}/map_column.json", "--robot", "{in}/robot.json",
                           "--out", "{case}/r.csv"], "encoder.left"),
    ("import-log-cell", ["import", "{in}/log_cell.csv", "--map", "{in}/map.json", "--robot", "{in}/robot.json",
                         "--out", "{case}/r.csv"], "log_cell.csv:3"),
    ("import-robot-ticks", ["import", "{in}/log.csv", "--map", "{in}/map.json", "--robot", "{in}/ticks.json",
                            "--out", "{case}/r.csv"], "ticks_per_rev"),
    ("import-out-folder", ["import", "{in}/log.csv", "--map", "{in}/map.json", "--robot", "{in}/robot.json",
                           "--out", "{case}/adir"], "adir"),
    ("import-out-in-a-file", ["import", "{in}/log.csv", "--map", "{in}/map.json", "--robot", "{in}/robot.json",
                              "--out", "{case}/afile/r.csv"], "afile"),
    # replay
    ("replay-missing", ["replay", "{case}/none.csv"], "none.csv"),
    ("replay-bad", ["replay", "{in}/bad.csv"], "bad.csv"),
    ("replay-start-beyond", ["replay", "{in}/run.csv", "--start", "99999"], "99999"),
    ("replay-start-negative", ["replay", "{in}/run.csv", "--start", "-1"], "'-1'"),
    ("replay-png-folder", ["replay", "{in}/run.csv", "--png", "{case}/adir"], "adir"),
    ("replay-params-bad", ["replay", "{in}/run.csv", "--params", "{in}/ticks.json"], "ticks_per_rev"),
    ("replay-robot-no-pose", ["replay", "{in}/robot.csv", "--world", "arena"], "tracker pose"),
    ("replay-substeps-zero", ["replay", "{in}/run.csv", "--substeps", "0"], "'0'"),
    # diagnose
    ("diagnose-missing", ["diagnose", "{case}/none.csv"], "none.csv"),
    ("diagnose-bad", ["diagnose", "{in}/bad.csv"], "bad.csv"),
    ("diagnose-json-folder", ["diagnose", "{in}/run.csv", "--json", "{case}/adir"], "adir"),
    ("diagnose-json-in-a-file", ["diagnose", "{in}/run.csv", "--json", "{case}/afile/v.json"], "afile"),
    ("diagnose-write-params-folder", ["diagnose", "{in}/run.csv", "--write-params", "{case}/adir"], "adir"),
    ("diagnose-params-bad", ["diagnose", "{in}/run.csv", "--params", "{in}/adc64.json"], "adc_bits"),
    ("diagnose-world-huge", ["diagnose", "{in}/run.csv", "--world", "{in}/huge.json"], "limit"),
    ("diagnose-workers-zero", ["diagnose", "{in}/run.csv", "--workers", "0"], "--workers"),
    # sweep
    ("sweep-out-missing", ["sweep", "--seeds", "1"], "--out"),
    ("sweep-seeds-zero", ["sweep", "--seeds", "0", "--out", "{case}/o"], "'0'"),
    ("sweep-rules-bogus", ["sweep", "--rules", "first,bogus", "--out", "{case}/o"], "bogus"),
    ("sweep-world-bogus", ["sweep", "--world", "paper_room,nowhere", "--out", "{case}/o"], "nowhere"),
    ("sweep-duration-nan", ["sweep", "--duration", "nan", "--out", "{case}/o"], "'nan'"),
    ("sweep-out-is-a-file", ["sweep", "--out", "{case}/afile"], "afile"),
    ("sweep-out-no-parent", ["sweep", "--out", "{case}/missing/o"], "missing"),
    ("sweep-scheduler-not-an-address", ["sweep", "--scheduler", "localhost", "--out", "{case}/o"], "'localhost'"),
    ("sweep-workers-zero", ["sweep", "--workers", "0", "--out", "{case}/o"], "'0'"),
    ("sweep-perturb-unknown", ["sweep", "--perturb", "whel_radius=0.1", "--out", "{case}/o"], "whel_radius"),
    ("sweep-perturb-not-a-number", ["sweep", "--perturb", "wheel_radius=lots", "--out", "{case}/o"], "'lots'"),
    ("sweep-perturb-no-rel", ["sweep", "--perturb", "wheel_radius", "--out", "{case}/o"], "NAME=REL"),
    ("sweep-perturb-rel-one", ["sweep", "--perturb", "wheel_radius=1", "--out", "{case}/o"], "[0, 1)"),
    ("sweep-perturb-rel-nan", ["sweep", "--perturb", "wheel_radius=nan", "--out", "{case}/o"], "[0, 1)"),
    ("sweep-perturb-zero-nominal", ["sweep", "--perturb", "backlash_l=0.1", "--out", "{case}/o"], "backlash_l"),
    ("sweep-perturb-whole-number", ["sweep", "--perturb", "adc_bits=0.1", "--out", "{case}/o"], "whole number"),
    ("sweep-perturb-list", ["sweep", "--perturb", "ir_gain_scale=0.1", "--out", "{case}/o"], "a list"),
    ("sweep-perturb-out-of-range", ["sweep", "--perturb", "gear_efficiency=0.2", "--out", "{case}/o"], "1.02"),
    ("sweep-perturb-twice", ["sweep", "--perturb", "wheel_radius=0.1,wheel_radius=0.2", "--out", "{case}/o"],
     "twice"),
    ("sweep-start-radius-negative", ["sweep", "--start-radius", "-0.1", "--out", "{case}/o"], "'-0.1'"),
    ("sweep-start-heading-over", ["sweep", "--start-heading", "200", "--out", "{case}/o"], "'200'"),
    # bench
    ("bench-no-benchmark", ["bench"], "BENCHMARK"),
    ("bench-firmware-cycles-zero", ["bench", "firmware", "--cycles", "0"], "'0'"),
    ("bench-firmware-json-in-a-file", ["bench", "firmware", "--json", "{case}/afile/x.json"], "afile"),
    ("bench-protocol-frames-zero", ["bench", "protocol", "--frames", "0"], "'0'"),
    ("bench-sim-seconds-nan", ["bench", "sim", "--seconds", "nan"], "'nan'"),
    ("bench-sim-batch-zero", ["bench", "sim", "--batch-n", "0"], "'0'"),
    ("bench-sim-json-folder", ["bench", "sim", "--json", "{case}/adir"], "adir"),
    ("bench-gui-frames-few", ["bench", "gui", "--frames", "5"], "'5'"),
    ("bench-gui-prerun-nan", ["bench", "gui", "--prerun", "nan"], "'nan'"),
    ("bench-diagnose-cases-zero", ["bench", "diagnose", "--cases", "0"], "'0'"),
    ("bench-diagnose-duration-short", ["bench", "diagnose", "--duration", "5"], "'5'"),
    ("bench-diagnose-workers-zero", ["bench", "diagnose", "--workers", "0"], "--workers"),
    ("bench-diagnose-jobs-zero", ["bench", "diagnose", "--jobs", "0"], "'0'"),
    ("bench-diagnose-out-in-a-file", ["bench", "diagnose", "--out", "{case}/afile/cases"], "afile"),
    ("bench-diagnose-json-folder", ["bench", "diagnose", "--json", "{case}/adir"], "adir"),
    ("bench-ghost-duration-short", ["bench", "ghost", "--duration", "1"], "'1'"),
    ("bench-ghost-plot-in-a-file", ["bench", "ghost", "--plot", "{case}/afile/x.png"], "afile"),
    ("bench-ghost-json-folder", ["bench", "ghost", "--json", "{case}/adir"], "adir"),
    # outputs tried by writing before any work: root may write anywhere os.access says, but not in /sys or
    # /proc, and /dev/full refuses every write (rows *-sys, *-proc, *-dev-full)
    ("diagnose-json-dev-full", ["diagnose", "{in}/run.csv", "--json", "/dev/full"], "/dev/full"),
    ("diagnose-json-sys", ["diagnose", "{in}/run.csv", "--json", "/sys/verdict.json"], "/sys/verdict.json"),
    ("diagnose-html-proc", ["diagnose", "{in}/run.csv", "--html", "/proc/report.html"], "/proc/report.html"),
    ("diagnose-write-params-sys", ["diagnose", "{in}/run.csv", "--write-params", "/sys/p.json"], "/sys/p.json"),
    ("sim-record-sys", ["sim", "--record", "/sys/run.csv"], "/sys/run.csv"),
    ("sim-record-dev-full", ["sim", "--record", "/dev/full"], "/dev/full"),
    ("sim-png-sys", ["sim", "--png", "/sys/run.png"], "/sys/run.png"),
    ("plot-recording-png-sys", ["plot", "recording", "{in}/run.csv", "--png", "/sys/r.png"], "/sys/r.png"),
    ("plot-worlds-out-proc", ["plot", "worlds", "--out", "/proc/nope"], "/proc/nope"),
    ("plot-sensor-out-sys", ["plot", "sensor", "--out", "/sys/figs"], "/sys/figs"),
    ("replay-png-sys", ["replay", "{in}/run.csv", "--png", "/sys/replay.png"], "/sys/replay.png"),
    ("sweep-out-proc", ["sweep", "--seeds", "1", "--out", "/proc/nope"], "/proc/nope"),
    ("sweep-out-sys", ["sweep", "--seeds", "1", "--out", "/sys/sweep"], "/sys/sweep"),
    ("demo-out-proc", ["demo", "--out", "/proc/nope/demo"], "/proc/nope/demo"),
    ("serial-record-sys", ["serial", "loop://", "--record", "/sys/r.csv", "--duration", "1"], "/sys/r.csv"),
    ("serial-record-dev-full", ["serial", "loop://", "--record", "/dev/full", "--duration", "1"], "/dev/full"),
    ("board-log-dev-full", ["board", "--log", "/dev/full"], "/dev/full"),
    ("board-flash-dir-proc", ["board", "--flash-dir", "/proc/nope"], "/proc/nope"),
    ("fuzzy-plot-sys", ["fuzzy", "--plot", "/sys/sets.png"], "/sys/sets.png"),
    ("gui-out-sys", ["gui", "--frames", "1", "--out", "/sys"], "/sys"),
    ("gui-save-sys", ["gui", "--frames", "1", "--save", "/sys/room.json"], "/sys/room.json"),
    ("gui-screenshot-dev-full", ["gui", "--frames", "1", "--screenshot", "/dev/full"], "/dev/full"),
    ("bench-sim-json-dev-full", ["bench", "sim", "--json", "/dev/full"], "/dev/full"),
    ("bench-protocol-json-sys", ["bench", "protocol", "--json", "/sys/p.json"], "/sys/p.json"),
    ("bench-firmware-json-proc", ["bench", "firmware", "--json", "/proc/f.json"], "/proc/f.json"),
    ("bench-diagnose-out-sys", ["bench", "diagnose", "--out", "/sys/cases"], "/sys/cases"),
    ("bench-diagnose-json-dev-full", ["bench", "diagnose", "--json", "/dev/full"], "/dev/full"),
    ("bench-ghost-plot-sys", ["bench", "ghost", "--plot", "/sys/ghost.png"], "/sys/ghost.png"),
    ("bench-ghost-json-dev-full", ["bench", "ghost", "--json", "/dev/full"], "/dev/full"),
    ("bench-sim-markdown-dev-full", ["bench", "sim", "--markdown", "/dev/full"], "/dev/full"),
    ("bench-sim-markdown-dev-null", ["bench", "sim", "--markdown", "/dev/null"], "not a regular file"),
    ("bench-gui-markdown-sys", ["bench", "gui", "--markdown", "/sys/b.md"], "/sys/b.md"),
]


IMPORT_MAP = {"time": {"column": "t", "unit": "ms"}, "command": {"kind": "current", "left": "il", "right": "ir",
                                                                 "unit": "mA"},
              "encoder": {"left": "el", "right": "er"}}


def make_inputs(folder: Path) -> None:
    """The input files the table refers to as {in}/NAME."""
    def world(size: list[float], **more: object) -> dict[str, object]:
        return {"name": "w", "size": size, "walls": [], "start": {"x": 0.5, "y": 0.5, "phi": 0.0}, **more}

    files = {
        "huge.json": world([1e9, 1e9]),
        "big.json": world([1000, 1000]),
        "walls.json": world([40, 40], walls=[{"segment": [1 + 0.3 * i, 2, 1.1 + 0.3 * i, 3]} for i in range(100)]),
        "lamp.json": world([2, 2], lamps=[{"x": 1, "y": 1, "level": 1e308}]),
        "far.json": world([2, 2], walls=[{"segment": [0, 0, 1e300, 1]}]),
        "adc64.json": {"adc_bits": 64},
        "ticks.json": {"ticks_per_rev": 0.5},
        "gains.json": {"ir_gain_scale": [1, 1, 1, 1, 1, 1, 1, 1e300]},
        "robot.json": {},
        "map.json": IMPORT_MAP,
        "map_kind.json": {**IMPORT_MAP, "command": {**IMPORT_MAP["command"], "kind": "pwm"}},  # type: ignore[dict-item]
        "map_column.json": {**IMPORT_MAP, "encoder": {"left": "nope", "right": "er"}},
    }
    for name, data in files.items():
        (folder / name).write_text(json.dumps(data))
    (folder / "latin1.json").write_bytes(json.dumps(world([2, 2], name="caf\u00e9"), ensure_ascii=False).encode("latin-1"))
    (folder / "bad.json").write_text('{"adc_bits": 12,')
    log = "t,il,ir,el,er\n" + "".join(f"{40 * k},100,100,{k},{k}\n" for k in range(5))
    (folder / "log.csv").write_text(log)
    (folder / "log_cell.csv").write_text(log.replace("40,100,100,1,1", "40,100,1x0,1,1"))
    (folder / "garbage.img").write_bytes(bytes(range(256)) * 64)
    (folder / "bad.csv").write_text("t,cmd_l\n0,0\n")
    (folder / "bad.csv.json").write_text(json.dumps({"format": "twinbot-recording", "version": 1,
                                                     "sample_period": 0.04}))
    r = run(["sim", "--world", "arena", "--duration", "0.4", "--record", str(folder / "run.csv")], REPO)
    assert r.returncode == 0, r.stderr
    # A robot's recording: no world in the sidecar, no tracker pose in the rows.
    lines = (folder / "run.csv").read_text().splitlines()
    (folder / "robot.csv").write_text("\n".join([lines[0]] + [row.rsplit(",", 3)[0] + ",,," for row in lines[1:]])
                                      + "\n")
    meta = json.loads((folder / "run.csv.json").read_text())
    meta.update(source="robot", world=None)
    (folder / "robot.csv.json").write_text(json.dumps(meta))


def make_case_folder(folder: Path) -> None:
    folder.mkdir()
    (folder / "afile").write_text("a file, not a folder\n")
    (folder / "adir").mkdir()
    (folder / "taken.csv.json").mkdir()  # the sidecar's name is taken by a folder


PRIVATE_TMP = Path(tempfile.mkdtemp(prefix="twinbot-bad-input-tmp-"))  # these runs' temporary directory alone


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    # cwd is the row's folder (relative default outputs would land there); the checkout comes first on the path;
    # TMPDIR is private, so what the runs leave there is theirs, whatever else runs on the machine.
    env = dict(os.environ, PYTHONPATH=str(REPO), TMPDIR=str(PRIVATE_TMP))
    return subprocess.run([sys.executable, "-m", "tools.cli.main", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=60, check=False)


def tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def board_folders() -> set[str]:
    return {p.name for p in PRIVATE_TMP.glob("twinbot-board-*")}


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[subprocess.CompletedProcess[str], set[str],
                                                                          set[str]]]:
    """Every row run once, concurrently: (result, the row's folder before, after)."""
    base = tmp_path_factory.mktemp("bad-input")
    inputs = base / "in"
    inputs.mkdir()
    make_inputs(inputs)
    inputs_before = tree(inputs)
    boards_before = board_folders()

    def one(case: tuple[str, list[str], str]) -> tuple[str, tuple[subprocess.CompletedProcess[str], set[str],
                                                                   set[str]]]:
        name, args, _ = case
        folder = base / name
        make_case_folder(folder)
        before = tree(folder)
        argv = [a.replace("{case}", str(folder)).replace("{in}", str(inputs)) for a in args]
        result = run(argv, folder)
        return name, (result, before, tree(folder))

    with ThreadPoolExecutor(max_workers=4) as pool:
        done = dict(pool.map(one, CASES))
    assert tree(inputs) == inputs_before, "a bad input changed the input files"
    assert board_folders() <= boards_before, "a twinbot-board-* folder was left in the temporary directory"
    return done


def test_the_table_covers_every_subcommand():
    from tools.cli.main import SUBCOMMANDS

    covered = {args[0] for _, args, _ in CASES if args}
    assert {name for name, _ in SUBCOMMANDS} <= covered
    assert len({name for name, _, _ in CASES}) == len(CASES)


@pytest.mark.parametrize("name,args,names", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_exit_2(outcomes, name, args, names):
    result, before, after = outcomes[name]
    lines = result.stderr.strip().splitlines()
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode == 2, (result.returncode, result.stdout[-500:], result.stderr[-500:])
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("twinbot") and "error:" in lines[0] and "None" not in lines[0], lines[0]
    assert names in lines[0], lines[0]
    assert after == before, f"left behind: {sorted(after - before)}"
