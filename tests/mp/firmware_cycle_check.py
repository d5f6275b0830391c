"""One control cycle allocates nothing: micropython tests/mp/firmware_cycle_check.py

Runs the firmware's Robot on the test HAL (firmware/hal_testbench.py), whose methods allocate nothing,
warms every path up (autonomous with obstacles, host commands, a parameter
change, the watchdog), then runs cycles inside micropython.heap_lock(): any
heap allocation raises MemoryError.  Host bytes (COMMAND frames) arrive
during the locked cycles, so the receive path is inside the proof too.
Prints 'cycle: ok N cycles' and the heap in use; exits 1 on failure.
"""
import gc
import struct
import sys

import micropython

from firmware.robot import Robot
from protocol import wire as M
from protocol.framing import FrameEncoder
from firmware.hal_testbench import TestHal


def command_frame(enc, mode, left, right):
    return enc.encode(M.COMMAND, struct.pack("<Bhh", mode, left, right))


def locked_cycles(robot, hal, frames, n, result):
    """n cycles under heap_lock; every 5th cycle a host COMMAND arrives."""
    k = 0
    micropython.heap_lock()
    try:
        while k < n:
            if k % 5 == 0:
                f = frames[(k // 5) % len(frames)]
                hal.in_pos = 0
                hal.in_len = len(f)
                for j in range(len(f)):
                    hal.inbox[j] = f[j]
            hal.reflection[k & 7] = (k * 37) % 3000
            robot.cycle()
            k += 1
    except MemoryError:
        micropython.heap_unlock()
        result[0] = k
        return
    micropython.heap_unlock()
    result[0] = -1


def main():
    hal = TestHal()
    robot = Robot(hal)
    enc = FrameEncoder()
    autonomous = command_frame(enc, M.MODE_AUTONOMOUS, 0, 0)
    host = command_frame(enc, M.MODE_HOST, 150, -120)
    # Warm up every path once: autonomous with obstacles, both rule sets,
    # host mode, watchdog, a parameter, a HELLO.
    hal.give(autonomous)
    for k in range(20):
        hal.reflection[k & 7] = 2500
        robot.cycle()
    hal.give(enc.encode(M.PARAM_SET, struct.pack("<Bi", 4, 0)))
    robot.cycle()
    hal.give(host)
    for k in range(12):
        robot.cycle()
    hal.give(enc.encode(M.HELLO, bytes(16)))
    robot.cycle()
    frames = []
    for r in range(2):
        for mode in (M.MODE_AUTONOMOUS, M.MODE_HOST, M.MODE_TELEOP):
            frames.append(command_frame(enc, mode, 100 - 50 * r, 80))
    result = [0]
    gc.collect()
    for averaging in (0, 1, 2, 3):
        robot.set_param(2, averaging)
        for rule_set in (0, 1):
            robot.set_param(4, rule_set)
            for odo in (0, 1, 2):
                robot.set_param(9, odo)
                robot.cycle()
                locked_cycles(robot, hal, frames, 60, result)
                if result[0] != -1:
                    print("cycle: FAIL allocation in locked cycle", result[0], "averaging", averaging,
                          "rule set", rule_set, "odometry", odo)
                    sys.exit(1)
    if robot.faults:
        print("cycle: FAIL", robot.faults, "faults")
        sys.exit(1)
    gc.collect()
    print("cycle: ok", 4 * 2 * 3 * 60, "cycles; heap in use", gc.mem_alloc(), "bytes")


main()
