"""The identification manoeuvre: wheel-speed commands that make the robot's physics show (docs/diagnosis.md).

An exploring robot never creeps, steps, reverses or pushes hard, so dry friction, delay,
backlash and traction stay hidden.  The manoeuvre asks for each in turn in HOST mode
(SEGMENTS: creep, steps, chirp, spins, arcs, reversals, bursts) and repeats.  Two guards on
what the robot reports keep it safe: a wall seen close ahead turns the command into a spin
away from it, and beyond `radius` from its start the robot drives back towards it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

GUARD_COUNTS = 250  # reflected counts (on - off): a wall a few cm away
FRONT = (0, 1, 7)  # S1, S2, S8
BACK = (3, 4, 5)  # S4, S5, S6


def _creep(t: float) -> tuple[float, float]:
    v = 25.0 if (t % 4.0) < 2.0 else -25.0
    return v, v


def _steps(t: float) -> tuple[float, float]:
    levels = (0.0, 150.0, 250.0, 0.0, -150.0, 0.0)
    v = levels[int(t / 1.0) % len(levels)]
    return v, v


def _chirp(t: float) -> tuple[float, float]:
    duration = 8.0
    f0, f1 = 0.2, 2.5
    phase = 2 * math.pi * (f0 * t + (f1 - f0) * t * t / (2 * duration))
    v = 120.0 * math.sin(phase)
    return v, v


def _spins(t: float) -> tuple[float, float]:
    v = 120.0 if (t % 4.0) < 2.0 else -120.0
    return -v, v


def _arcs(t: float) -> tuple[float, float]:
    return (200.0, 100.0) if (t % 6.0) < 3.0 else (100.0, 200.0)


def _reversals(t: float) -> tuple[float, float]:
    v = 80.0 if (t % 1.2) < 0.6 else -80.0
    return v, v


def _bursts(t: float) -> tuple[float, float]:
    v = 350.0 if (t % 2.0) < 0.8 else 0.0
    return v, v


SEGMENTS = (("creep", 8.0, _creep), ("steps", 6.0, _steps), ("chirp", 8.0, _chirp), ("spins", 8.0, _spins),
            ("arcs", 6.0, _arcs), ("reversals", 6.0, _reversals), ("bursts", 4.0, _bursts))
CYCLE_S = sum(d for _n, d, _f in SEGMENTS)


def schedule(t: float) -> tuple[str, float, float]:
    """(segment name, left, right) mm/s at time t of the manoeuvre, before the guards."""
    t = t % CYCLE_S
    for name, duration, f in SEGMENTS:
        if t < duration:
            left, right = f(t)
            return name, left, right
        t -= duration
    raise AssertionError("unreachable")


@dataclass
class Manoeuvre:
    radius: float = 0.5  # m from the start the robot may go
    guard_counts: int = GUARD_COUNTS
    guarded: int = 0  # commands the guards changed
    homing: int = 0

    def command(self, t: float, reflected: list[int] | tuple[int, ...] | None = None,
                odometry: tuple[float, float, float] | None = None) -> tuple[int, int]:
        """Wheel-speed set-points (mm/s) at time t, given the latest reflected counts and odometry (m, m, rad)."""
        _name, left, right = schedule(t)
        if odometry is not None and math.hypot(odometry[0], odometry[1]) > self.radius:
            self.homing += 1
            left, right = _towards_start(odometry)
        if reflected is not None:
            ahead = FRONT if left + right > 0 else BACK
            if left + right != 0 and max(reflected[k] for k in ahead) > self.guard_counts:
                self.guarded += 1
                left, right = -100.0, 100.0  # spin in place until the way is clear
        return int(round(left)), int(round(right))


def _towards_start(odometry: tuple[float, float, float]) -> tuple[float, float]:
    x, y, phi = odometry
    bearing = math.atan2(-y, -x) - phi
    bearing = (bearing + math.pi) % (2 * math.pi) - math.pi
    if abs(bearing) > math.pi / 3:  # face the start first
        return (-90.0, 90.0) if bearing > 0 else (90.0, -90.0)
    turn = 150.0 * bearing
    return 120.0 - turn, 120.0 + turn


def reflected_of(telemetry: dict[str, object] | None) -> list[int] | None:
    if telemetry is None:
        return None
    on, amb = telemetry["ir_on"], telemetry["ir_amb"]
    return [int(a) - int(b) for a, b in zip(on, amb)]  # type: ignore[call-overload]


def odometry_of(telemetry: dict[str, object] | None) -> tuple[float, float, float] | None:
    """The firmware's own odometry (m, m, rad), if its TELEMETRY carries it."""
    if telemetry is None or "odo_heading" not in telemetry:
        return None
    turns = int(telemetry["odo_heading"]) / float(1 << 30)  # type: ignore[call-overload]
    return (int(telemetry["odo_x"]) / 1e6, int(telemetry["odo_y"]) / 1e6,  # type: ignore[call-overload]
            2 * math.pi * (turns - 1.0 if turns > 0.5 else turns))


class ExcitedController:
    """The firmware in the loop (SIL or PIL) driven through the manoeuvre in HOST mode, as the harness drives
    a robot: each cycle one COMMAND, computed from the TELEMETRY the firmware last reported."""

    def __init__(self, inner: object, manoeuvre: Manoeuvre | None = None, cycle_s: float = 0.040) -> None:
        from protocol.framing import FrameEncoder

        self.inner = inner
        self.manoeuvre = manoeuvre or Manoeuvre()
        self.cycle_s = cycle_s
        self.name = f"{getattr(inner, 'name', '?')}, manoeuvre"
        self.t = 0.0
        self._frames: list[dict[str, object]] = []
        self._last: dict[str, object] | None = None
        self._enc = FrameEncoder()

    def cycle(self, s: object) -> object:
        from protocol import messages as M

        got = self.inner.telemetry()  # type: ignore[attr-defined]
        self._frames += got
        if got:
            self._last = got[-1]
        left, right = self.manoeuvre.command(self.t, reflected_of(self._last), odometry_of(self._last))
        payload = M.pack_payload(M.COMMAND, {"mode": M.MODE_HOST, "left": left, "right": right})
        self.inner.send(self._enc.encode(M.COMMAND, payload))  # type: ignore[attr-defined]
        self.t += self.cycle_s
        return self.inner.cycle(s)  # type: ignore[attr-defined]

    def telemetry(self, wait: float = 0.0) -> list[dict[str, object]]:
        got = self._frames + self.inner.telemetry(wait)  # type: ignore[attr-defined]
        self._frames = []
        return got

    def close(self) -> None:
        self.inner.close()  # type: ignore[attr-defined]
