"""Firmware golden vectors: micropython tests/mp/firmware_vectors_check.py tests/data/firmware_golden.jsonl

Replays every case of tests/data/make_firmware_vectors.py's file through the firmware and
compares every output exactly, a line at a time (a small heap is enough).  Prints
'firmware vectors: N cases ok (...)' or the first difference and exits 1.  CPython runs it
too (tests/test_firmware_vectors.py imports check_file).  With --locked (MicroPython only)
every firmware call runs inside heap_lock(): on a 32-bit port a value beyond +-2**30 is a
big int, an allocation, reported as 'FAIL line N ...: allocation in ...'.
"""
import json
import sys

from firmware.fuzzy import FuzzyController
from firmware.ir import IRArray
from firmware.odometry import Odometry
from firmware.wheels import WheelLoop

KINDS = ("fz", "ir", "od", "wh")
FORMAT_VERSION = 1


class Mismatch(Exception):
    pass


def wrap(count):
    """An encoder count as the HALs keep it, within [-2**29, 2**29) (as the generator's _wrap)."""
    half = 1 << 29
    if count >= half:
        return count - half - half
    if count < -half:
        return count + half + half
    return count


_lock = None  # micropython.heap_lock / heap_unlock under --locked


def call(fn, a=None, b=None, c=None, what=""):
    """fn(), fn(a), fn(a, b) or fn(a, b, c), inside heap_lock() under --locked (fn made beforehand: a bound
    method is an allocation)."""
    if _lock is not None:
        _lock[0]()
    try:
        if a is None:
            fn()
        elif b is None:
            fn(a)
        elif c is None:
            fn(a, b)
        else:
            fn(a, b, c)
    except MemoryError:
        if _lock is not None:
            _lock[1]()
        raise Mismatch("allocation in " + what)
    if _lock is not None:
        _lock[1]()


class ReplayHal:
    """Same behaviour as tests/data/make_firmware_vectors.ReplayHal: read_ir() gives
    the cycle's ambient readings while the emitters are off, 'on' ones while on."""

    def __init__(self):
        self.emitters = 0
        self.ambient = [0] * 8
        self.on = [0] * 8

    def set_emitters(self, pct):
        self.emitters = pct

    def read_ir(self, out):
        src = self.on if self.emitters else self.ambient
        for i in range(8):
            out[i] = src[i]


def expect(what, got, want):
    if got != want:
        raise Mismatch("{}: got {} expected {}".format(what, got, want))


class Checker:
    def __init__(self, header):
        if header.get("format") != FORMAT_VERSION:
            raise Mismatch("header: format {} expected {}".format(header.get("format"), FORMAT_VERSION))
        self.speed = header["fuzzy_speed"]
        self.every = header["odometry_every"]
        self.ctl = [FuzzyController(0, self.speed), FuzzyController(1, self.speed)]
        self.hal = ReplayHal()

    def fz(self, case):
        _k, readings, other, want = case
        got = []
        for speed in (self.speed, other):
            for rs in (0, 1):
                c = self.ctl[rs]
                call(c.configure, rs, speed, what="fuzzy configure")
                call(c.infer, readings, what="fuzzy infer")
                got.append(c.left)
                got.append(c.right)
        expect("left, right (rule set 0, 1) at max_speed {}, {}".format(self.speed, other), got, want)

    def ir(self, case):
        _k, power, method, window, inputs, want = case
        hal = self.hal
        arr = IRArray(hal, power, method, window)
        acquire = arr.acquire
        expect("cycles", len(inputs), len(want))
        for c in range(len(inputs)):
            cyc = inputs[c]
            hal.ambient = cyc[:8]
            hal.on = cyc[8:]
            call(acquire, what="IR acquire")
            got = list(arr.reflected) + list(arr.value) + [1 if arr.saturated else 0]
            expect("cycle {} reflected + value + saturated".format(c), got, want[c])

    def od(self, case):
        _k, d, w, tpr, start, steps, want = case
        n = len(steps) // 2
        for m in range(3):
            od = Odometry(d, w, tpr, m)
            call(od.configure, d, w, tpr, what="odometry configure")  # PARAM_SET's path
            step = od.step
            update = od.update
            expect("um_per_tick_q8, heading_per_tick", [od.um_per_tick_q8, od.heading_per_tick], want[:2])
            poses = []
            el = er = 0
            if start is not None:
                el = start[0]
                er = start[1]
                call(update, el, er, what="odometry update")
            for i in range(n):
                dl = steps[2 * i]
                dr = steps[2 * i + 1]
                if start is None:
                    call(step, dl, dr, what="odometry step")
                else:
                    el = wrap(el + dl)
                    er = wrap(er + dr)
                    call(update, el, er, what="odometry update")
                if (i + 1) % self.every == 0 or i == n - 1:
                    poses.append(od.x_um)
                    poses.append(od.y_um)
                    poses.append(od.heading)
            expect("method {} poses (x_um, y_um, heading)".format(m), poses, want[2 + m])

    def wh(self, case):
        _k, q8, kp, ki, limit, steps = case
        loop = WheelLoop(q8, kp, ki, limit)
        measure = loop.measure
        reset = loop.reset
        control = loop.control
        for i in range(len(steps)):
            ticks, dt, sp = steps[i][:3]
            call(measure, ticks, dt, what="wheel measure")
            if sp is None:
                call(reset, what="wheel reset")
            else:
                call(control, sp, dt, what="wheel control")
            got = [loop.speed, loop.current, loop.acc, 1 if loop.clamped else 0]
            expect("step {} speed, current, acc, clamped".format(i), got, steps[i][3:])


def check_file(path):
    """Check every case; return (counts per kind, total).  Raises Mismatch."""
    counts = {}
    for k in KINDS:
        counts[k] = 0
    with open(path) as f:
        header = json.loads(f.readline())
        checker = Checker(header)
        lineno = 1
        while True:
            line = f.readline()
            if not line:
                break
            lineno += 1
            case = json.loads(line)
            kind = case[0]
            if kind not in counts:
                raise Mismatch("line {}: unknown kind {!r}".format(lineno, kind))
            try:
                getattr(checker, kind)(case)
            except Mismatch as e:
                raise Mismatch("line {} ({} case {}): {}\n  case: {}".format(
                    lineno, kind, counts[kind], e, line.strip()))
            counts[kind] += 1
    total = 0
    for k in KINDS:
        if counts[k] != header["counts"][k]:
            raise Mismatch("{} cases: {} in the file, header says {}".format(k, counts[k], header["counts"][k]))
        total += counts[k]
    return counts, total


def main(argv):
    global _lock
    if len(argv) == 3 and argv[2] == "--locked":
        import micropython

        _lock = (micropython.heap_lock, micropython.heap_unlock)
        argv = argv[:2]
    if len(argv) != 2:
        print("usage: firmware_vectors_check.py FILE [--locked]")
        sys.exit(2)
    try:
        counts, total = check_file(argv[1])
    except Mismatch as e:
        print("firmware vectors: FAIL " + str(e))
        sys.exit(1)
    print("firmware vectors: {} cases ok ({}){}".format(
        total, ", ".join("{} {}".format(k, counts[k]) for k in KINDS), ", heap locked" if _lock else ""))


if __name__ == "__main__":
    main(sys.argv)
