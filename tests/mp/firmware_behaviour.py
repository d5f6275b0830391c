"""Behaviour of the firmware, checked on both interpreters.

Each check_* function drives firmware.robot.Robot on the TestHal and
asserts what a robot engineer would expect.  pytest runs every check on
CPython (tests/test_firmware_behaviour.py); run as a script, this file runs
them all under MicroPython and prints 'behaviour: N checks ok'.
"""
import struct
import sys

from check_runner import checks, run
from firmware.fuzzy import FuzzyController
from firmware.robot import BreakToRepl, Robot
from firmware.stall import StallGuard
from protocol import wire as W
from protocol.framing import FrameDecoder, FrameEncoder
from firmware.hal_testbench import TestHal

ENC = FrameEncoder()


def command(mode, left=0, right=0):
    return ENC.encode(W.COMMAND, struct.pack("<Bhh", mode, left, right))


def param_set(pid, value):
    return ENC.encode(W.PARAM_SET, struct.pack("<Bi", pid, value))


def frames_of(data):
    """(type, seq, payload) of every frame the robot sent."""
    return FrameDecoder().decode_all(data)


TELEMETRY_FMT = "<IBHii8H8HhhHhhiiiB"  # as firmware/robot.py
SP_L = 24  # indices in the unpacked TELEMETRY tuple
ODO_X = 26
ODO_HEADING = 28
EMITTER = 29


def telemetry(data):
    """Unpacked TELEMETRY tuples, oldest first."""
    return [struct.unpack(TELEMETRY_FMT, p) for t, _s, p in frames_of(data) if t == W.TELEMETRY]


def robot_with(rule_set=1, mode=W.MODE_AUTONOMOUS):
    hal = TestHal()
    robot = Robot(hal)
    hal.give(param_set(4, rule_set))
    hal.give(command(mode))
    robot.cycle()
    return hal, robot


def setpoints_for(rule_set, sensor, level=3000):
    hal, robot = robot_with(rule_set)
    if sensor >= 0:
        hal.reflection[sensor] = level
    for _ in range(3):
        robot.cycle()
    return robot.setpoint_l, robot.setpoint_r


def check_nothing_seen_goes_ahead():
    for rs in (0, 1):
        left, right = setpoints_for(rs, -1)
        assert left == right and left > 0, (rs, left, right)


def check_obstacle_front_goes_back():
    for rs in (0, 1):
        left, right = setpoints_for(rs, 0)
        assert left < 0 and right < 0, (rs, left, right)


def check_front_left_turns_right():
    left, right = setpoints_for(1, 1)  # S2
    assert left > 0 > right, (left, right)  # quick turn right
    left, right = setpoints_for(0, 1)
    assert left > right, (left, right)  # the first rule set turns, gently


def check_front_right_turns_left():
    left, right = setpoints_for(1, 7)  # S8
    assert right > 0 > left, (left, right)
    left, right = setpoints_for(0, 7)
    assert right > left, (left, right)


def check_sides_and_back():
    for rs in (0, 1):
        left, right = setpoints_for(rs, 2)  # S3 left: more right
        assert left > right > 0, (rs, left, right)
        left, right = setpoints_for(rs, 6)  # S7 right: more left
        assert right > left > 0, (rs, left, right)
        ahead = setpoints_for(rs, -1)[0]
        left, right = setpoints_for(rs, 4)  # S5 back: fast ahead
        assert left == right and left > ahead, (rs, left, right)


def check_mirror_symmetry():
    c = FuzzyController(1)
    for rs in (0, 1):
        c.configure(rs, 200)
        for k in range(200):
            r = [((k * 7919 + i * 104729) % 4096) for i in range(8)]
            mirrored = [r[(8 - i) % 8] for i in range(8)]
            c.infer(r)
            a = (c.left, c.right)
            c.infer(mirrored)
            assert (c.right, c.left) == a, (rs, r)


def check_ambient_subtraction_under_changing_light():
    hal, robot = robot_with(1, W.MODE_STOP)
    hal.reflection = [400, 0, 0, 0, 0, 0, 0, 300]
    seen = []
    for k in range(40):
        amb = 50 + (k * 97) % 1500  # a lamp flickering between cycles
        hal.ambient = [amb + 10 * i for i in range(8)]
        robot.cycle()
        seen.append(list(robot.ir.reflected))
        assert robot.ir.ambient[3] == amb + 30
    for r in seen:
        assert r == [240, 0, 0, 0, 0, 0, 0, 180], r  # 60 % emitter power, ambient gone


def check_saturation_flag():
    hal, robot = robot_with(1, W.MODE_STOP)
    hal.reflection[0] = 9000
    robot.cycle()
    assert robot.ir.saturated and robot.flags & W.FLAG_IR_SATURATED
    hal.reflection[0] = 100
    robot.cycle()
    assert not robot.flags & W.FLAG_IR_SATURATED


def check_watchdog_stops_motors():
    hal, robot = robot_with(1, W.MODE_HOST)
    hal.give(command(W.MODE_HOST, 150, 150))
    for _ in range(4):  # 160 ms of fresh commands: driving
        robot.cycle()
    assert robot.setpoint_l == 150 and hal.current[0] != 0
    assert not robot.flags & W.FLAG_WATCHDOG
    for _ in range(5):  # no COMMAND for 200 ms and more
        robot.cycle()
    assert robot.flags & W.FLAG_WATCHDOG
    assert hal.current == [0, 0], hal.current
    last = telemetry(hal.take_output())[-1]
    assert last[2] & W.FLAG_WATCHDOG and last[21] == 0 and last[22] == 0 and last[SP_L] == 0
    hal.give(command(W.MODE_HOST, 100, 100))  # commands again: driving again
    robot.cycle()
    assert not robot.flags & W.FLAG_WATCHDOG and robot.setpoint_l == 100


def check_watchdog_timeout_is_a_parameter():
    hal, robot = robot_with(1, W.MODE_TELEOP)
    hal.give(param_set(5, 1000))
    hal.give(command(W.MODE_TELEOP, 80, 80))
    for _ in range(20):  # 800 ms
        robot.cycle()
    assert not robot.flags & W.FLAG_WATCHDOG
    for _ in range(8):  # past 1000 ms
        robot.cycle()
    assert robot.flags & W.FLAG_WATCHDOG


def check_mode_changes():
    hal, robot = robot_with(1, W.MODE_STOP)
    robot.cycle()
    assert robot.mode == W.MODE_STOP and hal.current == [0, 0]
    for mode in (W.MODE_AUTONOMOUS, W.MODE_HOST, W.MODE_TELEOP, W.MODE_STOP):
        hal.give(command(mode, 120, 120))
        robot.cycle()
        assert robot.mode == mode
        tm = telemetry(hal.take_output())[-1]
        assert tm[1] == mode
    assert hal.current == [0, 0]
    hal.give(command(9, 0, 0))  # no such mode: refused, mode kept
    robot.cycle()
    assert robot.mode == W.MODE_STOP
    nacks = [struct.unpack("<3B", p) for t, _s, p in frames_of(hal.take_output()) if t == W.NACK]
    assert nacks and nacks[-1][1:] == (W.COMMAND, W.ERR_BAD_MODE)


def check_setpoints_limited_to_max_speed():
    hal, robot = robot_with(1, W.MODE_HOST)
    hal.give(command(W.MODE_HOST, 5000, -5000))
    robot.cycle()
    assert (robot.setpoint_l, robot.setpoint_r) == (200, -200)


def check_setpoints_limited_to_max_speed_in_both_directions_on_each_wheel():
    """The clamp keeps each wheel's sign: -300 on the left is -200, not +200."""
    for left, right in ((-5000, 5000), (-300, 300), (300, -300), (-201, 201)):
        hal, robot = robot_with(1, W.MODE_HOST)
        hal.give(command(W.MODE_HOST, left, right))
        robot.cycle()
        want = (200 if left > 0 else -200, 200 if right > 0 else -200)
        assert (robot.setpoint_l, robot.setpoint_r) == want, (left, right, robot.setpoint_l, robot.setpoint_r)


def check_the_first_mode_past_teleop_is_refused():
    hal, robot = robot_with(1, W.MODE_STOP)
    hal.take_output()
    hal.give(command(W.MODE_TELEOP + 1, 50, 50))
    robot.cycle()
    assert robot.mode == W.MODE_STOP
    nacks = [struct.unpack("<3B", p) for t, _s, p in frames_of(hal.take_output()) if t == W.NACK]
    assert nacks and nacks[-1][1:] == (W.COMMAND, W.ERR_BAD_MODE), nacks


def check_watchdog_trips_on_the_first_cycle_past_its_timeout():
    """watchdog_ms = 200 at a 40 ms cycle: 200 ms after the COMMAND is still in time, 240 ms is not."""
    hal, robot = robot_with(1, W.MODE_HOST)
    hal.give(command(W.MODE_HOST, 100, 100))
    robot.cycle()
    for _ in range(5):  # 200 ms since the COMMAND was read
        robot.cycle()
        assert not robot.flags & W.FLAG_WATCHDOG and robot.setpoint_l == 100
    robot.cycle()  # 240 ms
    assert robot.flags & W.FLAG_WATCHDOG and robot.setpoint_l == 0


def check_a_long_stall_counts_as_two_seconds():
    """A gap in the clock beyond 2000 ms (a stalled board) counts as 2000 ms in the wheel loops."""
    def after_gap(gap_ms):
        hal, robot = robot_with(1, W.MODE_AUTONOMOUS)
        for _ in range(5):
            robot.cycle()
        hal.t += gap_ms - 40  # wait_cycle adds the period itself
        robot.cycle()
        return robot.wheel_l.acc, robot.wheel_l.speed, hal.current[0]

    clamped = after_gap(2000)
    assert after_gap(8000) == clamped and after_gap(3000) == clamped
    assert after_gap(1900) != clamped


def check_parameters_set_get_and_refuse():
    hal, robot = robot_with(1, W.MODE_STOP)
    hal.take_output()
    hal.give(param_set(1, 80))
    hal.give(param_set(1, 101))
    hal.give(param_set(77, 1))
    hal.give(ENC.encode(W.PARAM_GET, bytes((6,))))
    robot.cycle()
    out = frames_of(hal.take_output())
    values = [struct.unpack("<Bi", p) for t, _s, p in out if t == W.PARAM_VALUE]
    nacks = [struct.unpack("<3B", p)[2] for t, _s, p in out if t == W.NACK]
    assert values == [(1, 80), (6, 40)], values
    assert nacks == [W.ERR_OUT_OF_RANGE, W.ERR_UNKNOWN_PARAM], nacks
    assert robot.ir.power == 80


def check_hello_answered():
    hal, robot = robot_with(1, W.MODE_STOP)
    hal.give(ENC.encode(W.HELLO, bytes(16)))
    robot.cycle()
    hellos = [struct.unpack("<6BIIH", p) for t, _s, p in frames_of(hal.take_output()) if t == W.HELLO]
    assert hellos and hellos[0][0] == W.PROTOCOL_VERSION and hellos[0][4] == W.BOARD_VIRTUAL
    assert hellos[0][6:] == (42000, 96000, 1200)


def check_telemetry_every_cycle_in_sequence():
    hal, robot = robot_with(1, W.MODE_AUTONOMOUS)
    hal.take_output()
    for _ in range(50):
        robot.cycle()
    dec = FrameDecoder()
    frames = dec.decode_all(hal.take_output())
    assert len([f for f in frames if f[0] == W.TELEMETRY]) == 50
    assert dec.seq_gaps == 0 and dec.errors == 0
    ticks = [t[0] for t in telemetry(b"".join(ENC.encode(f[0], f[2]) for f in frames))]
    assert ticks == sorted(ticks)


def held_cycles(hal, robot, n):
    """n cycles with both wheels held still (a wall, a wedge): the encoders never move.
    The setpoints and flags of each cycle, oldest first."""
    seen = []
    for _ in range(n):
        robot.cycle()
        hal.encs[0] = 0
        hal.encs[1] = 0
        seen.append((robot.setpoint_l, robot.setpoint_r, robot.flags & W.FLAG_STALL))
    return seen


def check_a_stalled_explorer_backs_out_then_turns_away_from_the_wall():
    hal, robot = robot_with(0)
    hal.reflection[2] = 600  # a wall on the left (S3): the explorer bears right, both wheels forward
    seen = held_cycles(hal, robot, 37)  # 1480 ms held: under stall_ms (1500)
    assert all(l > 0 and r > 0 and not f for l, r, f in seen), seen
    assert robot.wheel_l.current > 250 and robot.wheel_r.current > 250  # the loops wound up against the wall
    seen = held_cycles(hal, robot, 1)  # 1520 ms: it takes over and backs out
    assert seen[-1] == (-100, -100, W.FLAG_STALL), seen
    # at once: the push's integral is dropped, not unwound (that took longer than the whole back-out)
    assert robot.wheel_l.current < 0 and robot.wheel_r.current < 0, (robot.wheel_l.current, robot.wheel_r.current)
    assert telemetry(hal.take_output())[-1][2] & W.FLAG_STALL
    # 600 ms back (with the cycle that took over), 200 ms at rest, 700 ms spinning right (away from the
    # wall), 200 ms at rest, then the explorer has the wheels again: no wheel reverses at full speed
    seen = held_cycles(hal, robot, 14 + 5 + 18 + 5 + 1)
    runs = []
    for step in seen:
        if runs and runs[-1][0] == step:
            runs[-1][1] += 1
        else:
            runs.append([step, 1])
    stall = W.FLAG_STALL
    assert runs[:4] == [[(-100, -100, stall), 14], [(0, 0, stall), 5], [(100, -100, stall), 18], [(0, 0, stall), 5]], runs
    assert seen[-1][0] > 0 and seen[-1][1] > 0 and not seen[-1][2], seen
    assert robot.stall.escapes == 1
    hal.reflection[2] = 0
    hal.reflection[6] = 600  # the wall on the right (S7) now: the next spin is to the left
    seen = held_cycles(hal, robot, 37 + 15 + 5 + 1)
    assert seen[-1] == (-100, 100, W.FLAG_STALL), seen


def check_a_creeping_explorer_held_by_a_wall_backs_out_too():
    hal, robot = robot_with(0)
    hal.reflection[0] = 4000  # S1 saturated, S2 and S8 bright: the first rule set creeps on (docs/fuzzy.md)
    hal.reflection[1] = hal.reflection[7] = 3000
    seen = held_cycles(hal, robot, 38)
    assert seen[-2] == (22, 22, 0) and seen[-1] == (-100, -100, W.FLAG_STALL), seen


def check_wheels_that_turn_never_trip_the_stall_guard():
    hal, robot = robot_with(1)
    for _ in range(200):  # 8 s of free driving, starting from rest
        robot.cycle()
        assert not robot.flags & W.FLAG_STALL
    assert robot.setpoint_l == robot.setpoint_r == 110 and robot.stall.escapes == 0


def loaded_cycles(hal, robot, n, keep):
    """n cycles with the wheels turning at 1/keep of what the current gives free (a wall pushed, the
    wheels spinning on the floor): the encoders advance, but the current needed is keep times more.
    (setpoint, STALL flag, left current, left speed) of each cycle."""
    seen = []
    for _ in range(n):
        before = list(hal.encs)
        robot.cycle()
        for k in (0, 1):
            hal.encs[k] = before[k] + (hal.encs[k] - before[k]) // keep
        seen.append((robot.setpoint_l, robot.flags & W.FLAG_STALL, robot.wheel_l.current, robot.wheel_l.speed))
    return seen


def check_wheels_spinning_against_a_wall_back_out_on_their_current():
    """The wheels turn (at over a quarter of their setpoint: no stall by speed), but on three times
    the current free driving needs; past push_ma (parameter 16, 150 mA) that counts as stuck."""
    hal, robot = robot_with(1)
    hal.give(param_set(16, 0))  # the current rule off: the speed rule alone never trips
    seen = loaded_cycles(hal, robot, 100, 3)
    assert not any(f for _sp, f, _c, _v in seen) and seen[-1][2] > 150, seen
    assert all(4 * v >= sp for sp, _f, _c, v in seen[5:]), seen  # turning, not stalled
    hal, robot = robot_with(1)  # push_ma 150 mA, its default
    seen = loaded_cycles(hal, robot, 100, 3)
    first = [k for k, (_sp, f, _c, _v) in enumerate(seen) if f][0]
    over = [k for k, (_sp, _f, c, _v) in enumerate(seen) if c > 150][0]
    assert 0.04 * (first - over) == 1.52, (first, over, seen)  # 1500 ms over 150 mA, then it backs out
    assert seen[first][0] == -100 and robot.stall.escapes == 1


def check_a_push_by_fits_and_starts_counts_up_and_down():
    """Time stuck counts up while pushing, down while not: 3 cycles of 4 pushing trips the guard
    after 74 cycles (3 s), not 38 (1.5 s); one cycle of two never does."""
    for pushing, cycles in ((3, 74), (2, 0)):
        guard = StallGuard(1500, 150, 200)
        ir = [0] * 8
        tripped = 0
        for k in range(400):
            current = 300 if k % 4 < pushing else 50
            guard.steer(110, 110, 110, 110, current, current, 40, ir)
            if guard.state and not tripped:
                tripped = k + 1
        assert tripped == cycles, (pushing, tripped)


def check_an_explorer_whose_rules_cancel_out_is_stuck_too():
    """Both setpoints under 5 mm/s (the refined set's "back" and "go ahead" balanced at a wall): the
    wheels stand still, not stalled (nothing asked) nor pushing, and it backs out after stall_ms all
    the same; a wheel asked for 5 mm/s that turns at it is free."""
    ir = [0] * 8
    for left, right, speed, trips in ((3, -4, 0, True), (0, 0, 0, True), (5, 4, 5, False), (-4, 5, 5, False)):
        guard = StallGuard(1500, 150, 200)
        for _ in range(38):
            guard.steer(left, right, speed, speed, 10, 10, 40, ir)
        assert bool(guard.state) == trips and (guard.left, guard.right) == ((-100, -100) if trips else (left, right)), (
            left, right, guard.state)


def check_the_stall_guard_is_a_parameter_and_autonomous_only():
    hal, robot = robot_with(1)
    hal.give(param_set(15, 0))  # off: the explorer pushes on for ever
    seen = held_cycles(hal, robot, 100)
    assert all(l == r == 110 and not f for l, r, f in seen[1:]), seen
    hal.give(param_set(15, 400))  # 400 ms: ten cycles of 40 ms
    seen = held_cycles(hal, robot, 10)
    assert seen[-2][0] == 110 and seen[-1] == (-100, -100, W.FLAG_STALL), seen
    hal, robot = robot_with(1, W.MODE_HOST)  # the host drives: its commands stand, held or not
    for _ in range(100):
        hal.give(command(W.MODE_HOST, 150, 150))
        robot.cycle()
        hal.encs[0] = hal.encs[1] = 0
        assert (robot.setpoint_l, robot.setpoint_r) == (150, 150) and not robot.flags & W.FLAG_STALL


def noise_run(repl_link):
    """300 cycles of unfiltered random bursts with mpremote's 0D 03 planted inside them, at
    their start, and after silent cycles (on the UART only); the robot keeps driving."""
    hal, robot = robot_with(1, W.MODE_AUTONOMOUS)
    hal.repl_link = repl_link
    robot.repl_link = repl_link
    x = 987654321
    planted = 0
    for k in range(300):
        junk = bytearray(23)
        for j in range(23):
            x = (x * 1103515245 + 12345) & 0x7FFFFFFF
            junk[j] = (x >> 16) & 0xFF
        if k % 7 == 0:
            junk[0] = 0x0D  # a burst that begins like a break, but no silence before it
            junk[1] = 0x03
            planted += 1
        if k % 5 == 0:
            junk[9] = 0x0D
            junk[10] = 0x03
            planted += 1
        if k % 50 == 25 and not repl_link:
            robot.cycle()  # a silent cycle, then 0D 03 first: still noise on a UART
            hal.give(b"\r\x03")
            planted += 1
        hal.give(junk)
        if k % 10 == 0:
            hal.give(command(W.MODE_AUTONOMOUS))
        robot.cycle()
    assert planted > 100
    assert robot.cycles >= 300 and robot.faults == 0
    assert robot.rx.errors > 0  # the junk was seen and dropped
    assert robot.mode == W.MODE_AUTONOMOUS


def check_unfiltered_noise_does_not_stop_the_loop_on_usb():
    noise_run(True)


def check_unfiltered_noise_does_not_stop_the_loop_on_a_uart():
    noise_run(False)


def check_a_uart_never_breaks():
    hal, robot = robot_with(1, W.MODE_HOST)
    hal.repl_link = False
    robot = Robot(hal)
    robot.cycle()
    robot.cycle()  # silent
    hal.give(b"\r\x03\r\x01")
    assert not breaks(robot)


def check_break_needs_silence_before_it():
    hal, robot = robot_with(1, W.MODE_HOST)
    hal.give(b"\r\x03\r\x01")  # right after the setup frames: no silent cycle
    assert not breaks(robot)


def check_fault_while_driving_zeroes_the_currents_at_once():
    hal, robot = robot_with(1, W.MODE_HOST)
    for _ in range(5):
        hal.give(command(W.MODE_HOST, 150, -150))
        robot.cycle()
    assert hal.current[0] > 0 and hal.current[1] < 0, hal.current
    err = OSError(5)

    def broken(out):
        raise err

    hal.read_ir = broken  # every cycle now raises, before set_currents is reached
    hal.give(command(W.MODE_HOST, 150, -150))
    robot.run(1)
    assert hal.current == [0, 0], hal.current
    for _ in range(3):
        hal.give(command(W.MODE_HOST, 150, -150))
        robot.run(1)
        assert hal.current == [0, 0] and robot.mode == W.MODE_STOP
    logs = [p for t, _s, p in frames_of(hal.take_output()) if t == W.LOG]
    assert logs[0] == bytes([W.LOG_ERROR]) + b"fault #1 in cycle 6: OSError 5", logs[0]


def check_wheel_loops_restart_on_a_mode_change():
    accs = []
    for new_mode in (W.MODE_HOST, W.MODE_TELEOP):
        hal, robot = robot_with(1, W.MODE_HOST)
        for _ in range(10):
            hal.give(command(W.MODE_HOST, 150, 150))
            robot.cycle()
        hal.give(command(new_mode, 150, 150))
        robot.cycle()
        accs.append(robot.wheel_l.acc)
    same, changed = accs
    assert changed == 150 * 40, changed  # one step from zero: integral and speed were reset
    assert same > changed, (same, changed)


def check_telemetry_carries_the_firmwares_view():
    hal, robot = robot_with(1, W.MODE_HOST)
    hal.give(param_set(1, 70))
    for _ in range(10):
        hal.give(command(W.MODE_HOST, 120, 80))
        robot.cycle()
    tm = telemetry(hal.take_output())[-1]
    assert (tm[SP_L], tm[SP_L + 1]) == (120, 80)
    odo = robot.odometry
    assert (tm[ODO_X], tm[ODO_X + 1], tm[ODO_HEADING]) == (odo.x_um, odo.y_um, odo.heading)
    assert tm[ODO_X] > 0 and tm[ODO_HEADING] != 0
    assert tm[EMITTER] == 70


def check_geometry_parameters_reconfigure_the_odometry():
    hal, robot = robot_with(1, W.MODE_STOP)
    q8 = robot.odometry.um_per_tick_q8
    hal.give(param_set(12, 84000))  # twice the wheel diameter
    hal.give(param_set(14, 600))  # half the ticks per turn
    hal.give(param_set(13, 19999))  # below the range: refused
    robot.cycle()
    assert robot.odometry.um_per_tick_q8 == 4 * q8 or abs(robot.odometry.um_per_tick_q8 - 4 * q8) <= 2
    assert robot.wheel_l.um_per_tick_q8 == robot.odometry.um_per_tick_q8
    hal.give(ENC.encode(W.HELLO, bytes(16)))
    robot.cycle()
    out = frames_of(hal.take_output())
    hello = [struct.unpack("<6BIIH", p) for t, _s, p in out if t == W.HELLO][0]
    assert hello[6:] == (84000, 96000, 600), hello
    nacks = [struct.unpack("<3B", p)[2] for t, _s, p in out if t == W.NACK]
    assert nacks == [W.ERR_OUT_OF_RANGE]


class _BoardGeometry:  # what a robot_geometry.py written at flash time holds
    WHEEL_DIAMETER_UM = 50000
    WHEEL_BASE_UM = 110000
    TICKS_PER_REV = 2000


def check_geometry_file_of_the_board_is_used():
    sys.modules["robot_geometry"] = _BoardGeometry
    try:
        robot = Robot(TestHal())
    finally:
        del sys.modules["robot_geometry"]
    assert robot.params[12:15] == [50000, 110000, 2000], robot.params
    assert robot.odometry.um_per_tick_q8 == Robot(TestHal()).odometry.um_per_tick_q8 * 50000 * 1200 // (42000 * 2000) or \
        abs(robot.odometry.um_per_tick_q8 * 42000 * 2000 - Robot(TestHal()).odometry.um_per_tick_q8 * 50000 * 1200) < 42000 * 2000
    _BoardGeometry.TICKS_PER_REV = 3  # out of range: refused at start, naming it
    sys.modules["robot_geometry"] = _BoardGeometry
    try:
        Robot(TestHal())
        raise AssertionError("accepted ticks_per_rev 3")
    except ValueError as exc:
        assert "robot_geometry" in str(exc)
    finally:
        del sys.modules["robot_geometry"]
        _BoardGeometry.TICKS_PER_REV = 2000


def check_exception_in_a_cycle_is_survived():
    hal, robot = robot_with(1, W.MODE_HOST)

    def broken(out):
        raise OSError(5)

    hal.read_ir = broken
    robot.run(3)
    assert robot.faults == 3 and robot.mode == W.MODE_STOP
    assert hal.current == [0, 0]
    logs = [p for t, _s, p in frames_of(hal.take_output()) if t == W.LOG]
    assert logs and logs[0][0] == W.LOG_ERROR and b"OSError" in logs[0]
    del hal.read_ir  # repaired: the loop carries on and reports FAULT once
    robot.run(2)
    assert robot.faults == 3
    tms = telemetry(hal.take_output())
    assert tms[0][2] & W.FLAG_FAULT and not tms[-1][2] & W.FLAG_FAULT


def breaks(robot):
    """True if the next cycle stops the firmware for the REPL."""
    try:
        robot.cycle()
    except BreakToRepl:
        return True
    return False


def check_break_request_stops_and_leaves_the_rest():
    hal, robot = robot_with(1, W.MODE_HOST)
    robot.cycle()  # a silent cycle: mpremote starts on a quiet port
    hal.give(b"\r\x03\r\x01")  # mpremote: Ctrl-C, then Ctrl-A for the raw REPL
    assert breaks(robot)
    assert bytes(hal.inbox[hal.in_pos:hal.in_len]) == b"\r\x01"  # left for the REPL


def check_partial_frame_abandoned_after_silence():
    hal, robot = robot_with(1, W.MODE_STOP)
    frame = command(W.MODE_HOST, 50, 50)
    hal.give(frame[:5])  # the sender dies mid-frame
    robot.cycle()
    robot.cycle()  # a silent cycle: the partial frame is dropped
    assert robot.rx.abandoned == 1
    hal.give(b"\r\x03")
    assert breaks(robot)


def check_odometry_follows_the_wheels():
    hal, robot = robot_with(1, W.MODE_HOST)
    for _ in range(25):
        hal.give(command(W.MODE_HOST, 100, 100))
        robot.cycle()
    odo = robot.odometry
    assert odo.x_um > 0 and abs(odo.y_um) < odo.x_um // 20, (odo.x_um, odo.y_um)


CHECKS = checks(globals())


def main():
    run("behaviour", globals())


if __name__ == "__main__":
    main()
