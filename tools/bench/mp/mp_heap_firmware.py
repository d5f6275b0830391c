"""The MicroPython side of `twinbot bench firmware`: the heap of the loaded firmware.

The firmware's modules from .mpy plus a running Robot, on the test board
(firmware/hal_testbench.py), whose share and this script's are measured and
left out of `heap_in_use`.  The webassembly port collects only between
top-level execs, so tools/bench/firmware.py runs the parts there one exec at
a time.  Figures: docs/benchmarks.md.
"""
import gc
import json


def load():
    """Every firmware module the robot and its host link need."""
    import firmware.robot  # noqa: F401
    import protocol.framing  # noqa: F401


def board():
    from firmware.hal_testbench import TestHal

    return TestHal(256, 256)


def make_robot(hal):
    """A Robot in AUTONOMOUS mode after 20 cycles."""
    from firmware.robot import Robot
    from protocol import wire as W
    from protocol.framing import FrameEncoder

    robot = Robot(hal)
    hal.give(FrameEncoder().encode(W.COMMAND, bytes((W.MODE_AUTONOMOUS, 0, 0, 0, 0))))
    run_cycles(robot, hal, 20)
    return robot


def run_cycles(robot, hal, n):
    for k in range(n):
        hal.reflection[k & 7] = (k * 331) % 3000
        robot.cycle()


def figures(base, harness, robot):
    """One JSON line; call after a collection."""
    used = gc.mem_alloc()
    return json.dumps({"heap_in_use": used - base - harness, "harness_bytes": harness,
                       "heap_used_total": used, "cycles": robot.cycles, "faults": robot.faults})


def main(n):
    gc.collect()
    base = gc.mem_alloc()
    load()
    gc.collect()
    before = gc.mem_alloc()
    hal = board()
    gc.collect()
    harness = gc.mem_alloc() - before
    robot = make_robot(hal)
    run_cycles(robot, hal, n)
    gc.collect()
    print(figures(base, harness, robot))
