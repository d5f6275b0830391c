"""The MicroPython side of `twinbot bench firmware`: the control cycle's time and allocations.

    micropython tools/bench/mp/mp_firmware.py time N

Prints one JSON object.  The robot runs on firmware/hal_testbench.TestHal, whose own work (filling
the ADC readings, copying frames) is in the cycle time, as the ADC reads are on a board; the heap
figures come from mp_heap_firmware.py.  Figures: docs/benchmarks.md.
"""
import gc
import json
import sys
import time

import micropython


def make_hal():
    from firmware.hal_testbench import TestHal

    return TestHal(256, 256)


def make_robot(hal=None):
    # Imported here so that `heap` mode counts the firmware's modules.
    from firmware.robot import Robot
    from protocol import wire as W
    from protocol.framing import FrameEncoder

    if hal is None:
        hal = make_hal()
    robot = Robot(hal)
    enc = FrameEncoder()
    hal.give(enc.encode(W.COMMAND, bytes((W.MODE_AUTONOMOUS, 0, 0, 0, 0))))
    for k in range(20):
        hal.reflection[k & 7] = (k * 331) % 3000
        robot.cycle()
    return hal, robot


def median(xs):
    s = sorted(xs)
    return s[len(s) // 2]


def time_cycles(robot, hal, n, out):
    for k in range(n):
        hal.reflection[k & 7] = (k * 331) % 3000
        t0 = time.ticks_us()
        robot.cycle()
        out[k] = time.ticks_diff(time.ticks_us(), t0)


def per_call(fn, n):
    t0 = time.ticks_us()
    for _ in range(n):
        fn()
    return time.ticks_diff(time.ticks_us(), t0) / n


def bench_time(n):
    hal, robot = make_robot()
    durations = [0] * n
    gc.collect()
    time_cycles(robot, hal, n, durations)
    durations.sort()
    result = {
        "cycles": n,
        "cycle_us_median": durations[n // 2],
        "cycle_us_p90": durations[n * 9 // 10],
        "cycle_us_max": durations[-1],
    }
    result["parts_us"] = time_parts(robot, n)
    result["alloc_bytes_per_cycle"] = alloc_per_cycle(robot, hal, n, durations)
    result["heap_locked_cycles_ok"] = cycles_run_heap_locked(robot, hal, n, durations)
    result["faults"] = robot.faults
    return result


def time_parts(robot, n):
    # Microseconds per call of each part of the cycle.
    parts = {}
    ir = robot.ir
    parts["ir_acquire"] = per_call(ir.acquire, n)
    for rs in (0, 1):
        robot.fuzzy.configure(rs, 200)
        readings = robot.ir.value

        def infer():
            robot.fuzzy.infer(readings)

        parts["fuzzy_" + ("first" if rs == 0 else "refined")] = per_call(infer, n)
    wl = robot.wheel_l

    def pi():
        wl.measure(1234, 40)
        wl.control(150, 40)

    parts["wheel_pi_one_wheel"] = per_call(pi, n)
    odo = robot.odometry

    def step():
        odo.step(9, 11)

    parts["odometry_step"] = per_call(step, n)

    def telemetry():
        robot.send_telemetry(100, -100)

    parts["telemetry_frame"] = per_call(telemetry, n)
    return parts


def alloc_per_cycle(robot, hal, n, durations):
    # Allocations per cycle: the GC off, heap use before and after.
    gc.collect()
    gc.disable()
    before = gc.mem_alloc()
    time_cycles(robot, hal, n, durations)
    after = gc.mem_alloc()
    gc.enable()
    return (after - before) / n


def cycles_run_heap_locked(robot, hal, n, durations):
    # n cycles under heap_lock: any allocation raises.
    locked = [0]

    def run_locked():
        micropython.heap_lock()
        try:
            time_cycles(robot, hal, n, durations)
            locked[0] = 1
        except MemoryError:
            locked[0] = 0
        micropython.heap_unlock()

    run_locked()
    return bool(locked[0])


def main():
    what = sys.argv[1]
    n = int(sys.argv[2])
    if what != "time":
        raise SystemExit("usage: mp_firmware.py time N")
    result = bench_time(n)
    result["micropython"] = ".".join(str(v) for v in sys.implementation.version[:3])
    print(json.dumps(result))


if __name__ == "__main__":
    main()
