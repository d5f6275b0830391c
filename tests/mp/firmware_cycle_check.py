"""One control cycle allocates nothing: micropython tests/mp/firmware_cycle_check.py

Runs the firmware's Robot on a test HAL whose methods allocate nothing,
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


class TestHal:
    board = M.BOARD_VIRTUAL
    overrun = False

    def __init__(self):
        self.t = 0
        self.em = 0
        self.amb = [120, 130, 90, 80, 70, 85, 95, 110]
        self.refl = [0] * 8
        self.encs = [0, 0]
        self.cur_l = 0
        self.cur_r = 0
        self.inbox = bytearray(512)
        self.in_len = 0
        self.in_pos = 0
        self.sent = 0

    def wait_cycle(self, period):
        self.t += period
        return self.t

    def set_emitters(self, pct):
        self.em = pct

    def read_ir(self, out):
        for i in range(8):
            v = self.amb[i] + (self.refl[i] * self.em) // 100
            out[i] = v if v < 4095 else 4095

    def read_encoders(self, out):
        out[0] = self.encs[0]
        out[1] = self.encs[1]

    def battery_mv(self):
        return 7400

    def set_currents(self, left, right):
        self.cur_l = left
        self.cur_r = right
        self.encs[0] += left // 16
        self.encs[1] += right // 16

    def host_read(self, buf):
        n = self.in_len - self.in_pos
        if n > len(buf):
            n = len(buf)
        for k in range(n):
            buf[k] = self.inbox[self.in_pos + k]
        self.in_pos += n
        return n

    def host_write(self, data):
        self.sent += len(data)

    def end_cycle(self):
        pass

    def give(self, frame):
        """Queue host bytes (setup only)."""
        self.in_pos = 0
        self.in_len = len(frame)
        for k in range(len(frame)):
            self.inbox[k] = frame[k]


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
            hal.refl[k & 7] = (k * 37) % 3000
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
        hal.refl[k & 7] = 2500
        robot.cycle()
    hal.give(enc.encode(M.PARAM_SET, struct.pack("<Bi", 4, 0)))
    robot.cycle()
    hal.give(host)
    for k in range(12):
        robot.cycle()
    hal.give(enc.encode(M.HELLO, bytes(6)))
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
