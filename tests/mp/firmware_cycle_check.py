"""One control cycle allocates nothing: micropython tests/mp/firmware_cycle_check.py

Runs the firmware's Robot on the test HAL (firmware/hal_testbench.py), warms every path up,
then runs cycles inside micropython.heap_lock() while host frames arrive: every message
type, every parameter at its minimum and maximum (each followed by driving cycles),
out-of-range and unknown parameters, and hostile frames.  The decoder's counters and the
parameters applied are checked afterwards, so a frame cannot pass by being ignored.
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


def hostile_and_every_message(enc):
    """(frames, expected (pid, value) after each frame or (-1, -1)), built before locking."""
    frames = []
    expect = []

    def add(frame, pid=-1, value=-1):
        frames.append(frame)
        expect.append((pid, value))

    drive = command_frame(enc, M.MODE_HOST, 150, -120)
    limits = M.PARAM_LIMITS
    for pid in range(1, len(limits) // 3):
        lo, hi, default = limits[3 * pid], limits[3 * pid + 1], limits[3 * pid + 2]
        for value in (lo, hi, hi + 1, lo - 1, default):
            ok = lo <= value <= hi
            add(enc.encode(M.PARAM_SET, struct.pack("<Bi", pid, value)), pid if ok else -1, value)
            add(drive)
        add(enc.encode(M.PARAM_GET, struct.pack("<B", pid)))
    add(enc.encode(M.PARAM_SET, struct.pack("<Bi", 0, 1)))
    add(enc.encode(M.PARAM_SET, struct.pack("<Bi", 200, 1)))
    add(enc.encode(M.PARAM_GET, struct.pack("<B", 99)))
    add(enc.encode(M.HELLO, bytes(16)))
    add(command_frame(enc, 7, 10, 10))  # a mode that does not exist
    for t in (M.TELEMETRY, M.PARAM_VALUE, M.ACK, M.NACK, M.HW_SENSE, M.HW_ACTUATE, M.LOG):
        add(enc.encode(t, bytes(M.PAYLOAD_SIZE[t] + (20 if t == M.LOG else 0))))
    bad = bytearray(drive)
    bad[4] ^= 0x10
    add(bytes(bad))  # bad CRC
    add(enc.encode(M.COMMAND, bytes(4)))  # wrong length
    add(enc.encode(0x1F, bytes(3)))  # unknown type
    add(b"\x00" + b"\x5a" * 400 + b"\x00")  # oversize
    x = 99
    for burst in range(6):  # junk bursts, 0x00 and 0x0D included (not right after silence)
        g = bytearray(40 + 17 * burst)
        g[0] = 0x00
        for k in range(1, len(g)):
            x = (x * 1103515245 + 12345) & 0x7FFFFFFF
            g[k] = (x >> 16) & 0xFF
        add(bytes(g))
        add(drive)
    return frames, expect


def locked_frames(robot, hal, frames, expect, per, result):
    """Each frame delivered, then `per` cycles, all under heap_lock; result[0] = frames done (-1: all),
    result[1] = parameter changes seen applied."""
    k = 0
    micropython.heap_lock()
    try:
        while k < len(frames):
            f = frames[k]
            hal.in_pos = 0
            hal.in_len = len(f)
            for j in range(len(f)):
                hal.inbox[j] = f[j]
            for c in range(per):
                hal.reflection[c & 7] = (k * 37 + c) % 3000
                robot.cycle()
            pv = expect[k]
            if pv[0] >= 0 and robot.params[pv[0]] == pv[1]:
                result[1] += 1
            hal.out_len = 0
            k += 1
    except MemoryError:
        micropython.heap_unlock()
        result[0] = k
        return
    micropython.heap_unlock()
    result[0] = -1


def check_every_message(robot, hal, enc):
    frames, expect = hostile_and_every_message(enc)
    want_applied = 0
    for pid, _v in expect:
        if pid >= 0:
            want_applied += 1
    dec = robot.rx
    before = dec.stats()
    result = [0, 0]
    gc.collect()
    locked_frames(robot, hal, frames, expect, 3, result)
    if result[0] != -1:
        print("cycle: FAIL allocation in locked cycle after frame", result[0], "of", len(frames), frames[result[0]])
        sys.exit(1)
    if result[1] != want_applied:
        print("cycle: FAIL", result[1], "parameter changes applied, expected", want_applied)
        sys.exit(1)
    after = dec.stats()
    for key in ("crc_errors", "length_errors", "unknown_types", "overflows"):
        if after[key] <= before[key]:
            print("cycle: FAIL no", key, "counted:", after)
            sys.exit(1)
    if robot.faults:
        print("cycle: FAIL", robot.faults, "faults")
        sys.exit(1)
    return len(frames) * 3


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
    n = check_every_message(robot, hal, enc)
    gc.collect()
    print("cycle: ok", 4 * 2 * 3 * 60 + n, "cycles; heap in use", gc.mem_alloc(), "bytes")


main()
