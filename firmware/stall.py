"""The explorer's stall guard: back out instead of pushing a wall for ever (docs/firmware.md).

The robot is stuck while a wheel turns at under a quarter of the speed it is asked for
(or the wrong way), while a wheel's current reference is above push_ma, or while both
setpoints are under _STALL_MIN_SPEED.  At stall_ms of being stuck the guard backs, rests,
spins away from the brighter side, rests, and hands the wheels back.  stall_ms = 0 turns
it off, push_ma = 0 its current rule.  Integers only and no allocation, like the cycle.
"""
from protocol.compat import const

_STALL_MIN_SPEED = const(5)  # mm/s: a setpoint below this asks the wheel to stand (it may rest on a tick)
_BACK_MS = const(600)  # ~6 cm back at the default 100 mm/s
_TURN_MS = const(700)  # ~80 degrees at 100 mm/s a wheel on the 96 mm axle
_HALT_MS = const(200)  # the wheels brought to rest between moves: no wheel reverses at full speed
_WATCHING = const(0)
_BACKING = const(1)
_HALTING = const(2)  # after backing, before the turn
_TURNING = const(3)
_SETTLING = const(4)  # after the turn, before the explorer has the wheels again


def _standing(left: int, right: int) -> bool:
    """Both setpoints too small to move a wheel: the explorer's rules cancel out."""
    return -_STALL_MIN_SPEED < left < _STALL_MIN_SPEED and -_STALL_MIN_SPEED < right < _STALL_MIN_SPEED


def _stalled(setpoint: int, speed: int) -> bool:
    """A wheel asked to turn that turns at under a quarter of its setpoint, or the other way."""
    if setpoint >= _STALL_MIN_SPEED:
        return 4 * speed < setpoint
    if setpoint <= -_STALL_MIN_SPEED:
        return 4 * speed > setpoint
    return False


class StallGuard:
    """steer() passes the explorer's setpoints through, or replaces them while backing out (state is
    not _WATCHING).  stall_ms, push_ma and max_speed are set as attributes (RAM is scarce: no setter)."""

    def __init__(self, stall_ms: int, push_ma: int, max_speed: int) -> None:
        self.stall_ms = stall_ms
        self.push_ma = push_ma
        self.max_speed = max_speed
        self.left = 0
        self.right = 0
        self.state = _WATCHING
        self.stalled_ms = 0  # time stuck (counted up while stalled or pushing, down while not), while watching
        self.phase_ms = 0  # time spent backing or turning
        self.spin = 1  # +1: spin clockwise (to the right), -1: counter-clockwise
        self.escapes = 0  # times it took over since start

    def reset(self) -> None:
        self.state = _WATCHING
        self.stalled_ms = 0
        self.phase_ms = 0

    def steer(self, left: int, right: int, speed_l: int, speed_r: int, current_l: int, current_r: int,
              dt_ms: int, ir: list[int]) -> None:
        """The setpoints (mm/s) for this cycle: the explorer's (left, right) or the guard's.
        speed_l, speed_r: the wheels' measured speeds, mm/s; current_l, current_r: their last current
        references, mA; ir: the eight reflected readings."""
        state = self.state
        if not self.stall_ms:  # off: nothing counts, so that turning it on starts afresh
            self.reset()
            self.left = left
            self.right = right
            return
        if state == _WATCHING:
            push = self.push_ma
            if _stalled(left, speed_l) or _stalled(right, speed_r) or _standing(left, right) or (
                    push and (current_l > push or current_l < -push or current_r > push or current_r < -push)):
                self.stalled_ms += dt_ms
            elif self.stalled_ms > dt_ms:
                self.stalled_ms -= dt_ms
            else:
                self.stalled_ms = 0
            if self.stalled_ms < self.stall_ms:
                self.left = left
                self.right = right
                return
            self.state = state = _BACKING
            self.phase_ms = 0
            self.stalled_ms = 0
            if self.escapes < 0x3FFFFFFF:  # saturates inside the RP2040's small ints
                self.escapes += 1
            # Spin away from the side that sees more: S2..S4 are on the left, S6..S8 on the right.
            seen_left = ir[1] + ir[2] + ir[3]
            seen_right = ir[5] + ir[6] + ir[7]
            if seen_left > seen_right:
                self.spin = 1
            elif seen_right > seen_left:
                self.spin = -1
            else:
                self.spin = -self.spin
        else:
            self.phase_ms += dt_ms
            if self.phase_ms >= (_BACK_MS if state == _BACKING else _TURN_MS if state == _TURNING else _HALT_MS):
                self.phase_ms = 0
                if state == _SETTLING:
                    self.reset()
                    self.left = left
                    self.right = right
                    return
                self.state = state = state + 1
        v = self.max_speed // 2
        if state == _BACKING:
            self.left = -v
            self.right = -v
        elif state == _TURNING:
            self.left = v * self.spin
            self.right = -v * self.spin
        else:
            self.left = 0
            self.right = 0
