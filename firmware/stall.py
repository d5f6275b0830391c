"""The explorer's stall guard: back out instead of pushing a wall for ever.

The fuzzy explorer sees walls only through its IR ring.  Wedged nose first
into a gap narrower than the robot (the two front-side sensors see walls, the
front one sees the gap) it drives on with its wheels held still; the speed
loops wind up to the current limit and stay there, each motor at its stall
current for as long as the run lasts.  The guard watches the wheels: when one
is asked for at least STALL_MIN_SPEED and turns at under a quarter of that (or
the wrong way) for stall_ms, it takes over: BACK_MS with both wheels back,
then TURN_MS spinning on the spot away from the side whose IR sees more light
(alternating when both see the same), both at half max_speed; then the
explorer has the wheels again.  stall_ms = 0 turns the guard off.

Integers only and no allocation, like the rest of the control cycle.
"""
from protocol.compat import const

STALL_MIN_SPEED = const(5)  # mm/s: a setpoint below this is "stand still" (the wheel may rest on a tick), never a stall
BACK_MS = const(600)  # ~6 cm back at the default 100 mm/s
TURN_MS = const(700)  # ~80 degrees at 100 mm/s a wheel on the 96 mm axle
WATCHING = const(0)
BACKING = const(1)
TURNING = const(2)


def _stalled(setpoint: int, speed: int) -> bool:
    """A wheel asked to turn that turns at under a quarter of its setpoint, or the other way."""
    if setpoint >= STALL_MIN_SPEED:
        return 4 * speed < setpoint
    if setpoint <= -STALL_MIN_SPEED:
        return 4 * speed > setpoint
    return False


class StallGuard:
    """steer() passes the explorer's setpoints through, or replaces them while backing out (state is
    not WATCHING).  stall_ms and max_speed are set as attributes (RAM is scarce: no setter)."""

    def __init__(self, stall_ms: int, max_speed: int) -> None:
        self.stall_ms = stall_ms
        self.max_speed = max_speed
        self.left = 0
        self.right = 0
        self.state = WATCHING
        self.stalled_ms = 0  # how long a wheel has been stalled, while watching
        self.phase_ms = 0  # time spent backing or turning
        self.spin = 1  # +1: spin clockwise (to the right), -1: counter-clockwise
        self.escapes = 0  # times it took over since start

    def reset(self) -> None:
        self.state = WATCHING
        self.stalled_ms = 0
        self.phase_ms = 0

    def steer(self, left: int, right: int, speed_l: int, speed_r: int, dt_ms: int, ir: list[int]) -> None:
        """The setpoints (mm/s) for this cycle: the explorer's (left, right) or the guard's.
        speed_l, speed_r: the wheels' measured speeds, mm/s; ir: the eight reflected readings."""
        state = self.state
        if state == WATCHING:
            if self.stall_ms and (_stalled(left, speed_l) or _stalled(right, speed_r)):
                self.stalled_ms += dt_ms
            else:
                self.stalled_ms = 0
            if not self.stall_ms or self.stalled_ms < self.stall_ms:
                self.left = left
                self.right = right
                return
            self.state = state = BACKING
            self.phase_ms = 0
            self.stalled_ms = 0
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
            if state == BACKING and self.phase_ms >= BACK_MS:
                self.state = state = TURNING
                self.phase_ms = 0
            elif state == TURNING and self.phase_ms >= TURN_MS:
                self.reset()
                self.left = left
                self.right = right
                return
        v = self.max_speed // 2
        if state == BACKING:
            self.left = -v
            self.right = -v
        else:
            self.left = v * self.spin
            self.right = -v * self.spin
