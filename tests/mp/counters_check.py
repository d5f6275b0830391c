"""Every counter and accumulator crosses its 31-bit limit without a heap allocation: micropython counters_check.py

The RP2040's small ints hold [-2**30, 2**30).  Each check puts one counter a step below its limit,
then runs the code that moves it past, inside micropython.heap_lock(): the cycle counter, the fault
counter, the IR averaging count, the stall guard's escapes, every decoder counter, odometry x and y,
a PARAM_SET of 2**30 and more, and the virtual board's clock and encoder fields.  The same checks
run on CPython (tests/test_firmware_counters.py), so every interpreter saturates or wraps alike.
Prints 'counters: N checks ok'; exits 1 on failure.
"""
import struct

try:
    import micropython
except ImportError:  # CPython: no heap lock, the values are still checked
    micropython = None

from check_runner import checks, run
from firmware.robot import Robot
from firmware.hal_testbench import TestHal
from protocol import cobs, fields
from protocol import wire as W
from protocol.framing import FrameDecoder, FrameEncoder

SAT = 0x3FFFFFFF
ENC = FrameEncoder()


def locked(fn):
    """fn() under heap_lock where there is one; True when it allocated (fn takes no arguments:
    a call with *args builds a tuple)."""
    if micropython is None:
        fn()
        return False
    micropython.heap_lock()
    try:
        fn()
    except MemoryError:
        micropython.heap_unlock()
        return True
    micropython.heap_unlock()
    return False


def cycles(robot, n):
    for _ in range(n):
        robot.cycle()


def give(hal, frame):
    hal.in_pos = 0
    hal.in_len = len(frame)
    for j in range(len(frame)):
        hal.inbox[j] = frame[j]


def robot_in(mode, hal=None):
    hal = hal or TestHal()
    robot = Robot(hal)
    give(hal, ENC.encode(W.COMMAND, struct.pack("<Bhh", mode, 100, 100)))
    cycles(robot, 3)
    hal.take_output()
    return hal, robot


def check_cycle_counter_saturates():
    hal, robot = robot_in(W.MODE_HOST)
    robot.cycles = SAT - 2
    assert not locked(lambda: cycles(robot, 5)), "allocation"
    assert robot.cycles == SAT, robot.cycles


def check_fault_counter_saturates():
    hal, robot = robot_in(W.MODE_STOP)
    robot.faults = SAT - 1
    robot.cycles = SAT
    exc = ValueError(123)
    assert not locked(lambda: robot.on_fault(exc)), "allocation"
    assert not locked(lambda: robot.on_fault(exc)), "allocation"
    assert robot.faults == SAT, robot.faults
    logs = [p for t, _s, p in FrameDecoder().decode_all(hal.take_output()) if t == W.LOG]
    assert logs and b"fault #1073741823 in cycle 1073741823" in bytes(logs[-1]), logs


def check_ir_average_count_saturates():
    hal, robot = robot_in(W.MODE_STOP)
    robot.ir.configure(60, 1, 4)  # moving average of 4
    cycles(robot, 6)
    robot.ir._count = SAT - 1
    hal.reflection[0] = 2000
    assert not locked(lambda: cycles(robot, 6)), "allocation"
    assert robot.ir._count == SAT, robot.ir._count
    assert robot.ir.value[0] == 2000 * 60 // 100, robot.ir.value[0]  # the window is full: the plain mean


def check_stall_escapes_saturate():
    hal, robot = robot_in(W.MODE_AUTONOMOUS)
    robot.stall.escapes = SAT

    def held():
        for _ in range(150):
            robot.cycle()
            hal.encs[0] = 0  # wheels held: the stall guard backs out
            hal.encs[1] = 0

    assert not locked(held), "allocation"
    assert robot.stall.escapes == SAT, robot.stall.escapes


def frame(msg_type, payload, seq):
    enc = FrameEncoder()
    enc.seq = seq
    return enc.encode(msg_type, payload)


def check_decoder_counters_saturate():
    dec = FrameDecoder()
    good = frame(W.COMMAND, struct.pack("<Bhh", 0, 0, 0), 0)
    jump = frame(W.COMMAND, struct.pack("<Bhh", 0, 0, 0), 201)
    bad_crc = frame(W.COMMAND, struct.pack("<Bhh", 0, 0, 1), 1)
    body = bytearray(cobs.decode(bad_crc[1:-1]))
    body[3] ^= 1  # the mode byte: the CRC no longer matches
    bad_crc = b"\x00" + cobs.encode(body) + b"\x00"
    names = ("frames", "frames_lost", "seq_gaps", "crc_errors", "overflows", "abandoned")
    for name in names:
        setattr(dec, name, SAT - 1)
    junk = bytearray(300)
    for k in range(300):
        junk[k] = 1 + k % 200

    stream = (good, jump, good, bad_crc, bad_crc, junk, b"\x00", junk, b"\x00")  # built before the lock

    def feed_all():
        for data in stream:
            i = 0
            while i < len(data):
                i = dec.feed(data, i, len(data))
        for _ in range(2):
            dec.feed(b"\x00\x01", 0, 2)
            dec.abandon_partial()

    assert not locked(feed_all), "allocation"
    for name in names:
        assert getattr(dec, name) == SAT, (name, getattr(dec, name))


def check_odometry_wraps_at_2_pow_29_um():
    hal, robot = robot_in(W.MODE_HOST)
    odo = robot.odometry
    odo.x_um = 0x20000000 - 5000  # 5 mm before the wrap, driving ahead
    odo.y_um = -0x20000000 + 10

    order = ENC.encode(W.COMMAND, struct.pack("<Bhh", W.MODE_HOST, 150, 150))

    def drive():
        for _ in range(10):
            give(hal, order)
            robot.cycle()

    assert not locked(drive), "allocation"
    assert -0x20000000 <= odo.x_um < -0x20000000 + 100000, odo.x_um  # wrapped, a few cm past
    assert -0x20000000 <= odo.y_um < 0x20000000, odo.y_um
    tm = [p for t, _s, p in FrameDecoder().decode_all(hal.take_output()) if t == W.TELEMETRY]
    assert struct.unpack_from("<i", tm[-1], struct.calcsize("<IBHii8H8HhhHhh"))[0] == odo.x_um


def check_param_set_of_2_pow_30_and_more_is_refused():
    hal, robot = robot_in(W.MODE_STOP)
    frames = [frame(W.PARAM_SET, struct.pack("<Bi", 1, v), k) for k, v in
              enumerate((0x40000000, 0x7FFFFFFF, -0x80000000, -0x40000001))]

    def send():
        for f in frames:
            give(hal, f)
            robot.cycle()

    assert not locked(send), "allocation"
    nacks = [p[2] for t, _s, p in FrameDecoder().decode_all(hal.take_output()) if t == W.NACK]
    assert nacks == [W.ERR_OUT_OF_RANGE] * 4, nacks
    assert robot.params[1] == 60


def check_clock_and_encoder_fields_wrap():
    body = bytearray(8)
    out = [0, 0, 0, 0]
    struct.pack_into("<iI", body, 0, -0x7FFFFFF0, 0xFFFFFFF0)

    def read():
        out[0] = fields.read_wrap30(body, 0)
        out[1] = fields.read_u30(body, 4)
        out[2] = fields.read_i31(body, 0)
        out[3] = fields.read_i31(body, 4)

    assert not locked(read), "allocation"
    assert out[0] == 16 and out[1] == 0x3FFFFFF0, out  # -2**31 + 16 and 2**32 - 16 modulo 2**30
    assert out[2] == -0x40000000 and out[3] == -16, out


CHECKS = checks(globals())


def main():
    run("counters", globals())


if __name__ == "__main__":
    main()
