"""The late-signal twin: a ghost robot that says where the robot is NOW when its signal arrives late.

The ghost estimates the link's latency from each TELEMETRY frame's tick against its
arrival (the link's floor is an input: one direction cannot see it), keeps the HOST-mode
commands the host sent, and `predict(now)` advances the last frame's odometry pose through
them with a kinematic model of the firmware's wheel loops (a dead time `dead_s`, then a
first-order lag `tau_s`).  Each new frame replaces the state (docs/late-signal-twin.md).
"""
from __future__ import annotations

import bisect
import math
from collections import deque

TURN = float(1 << 30)  # odo_heading units per turn


class Ghost:
    def __init__(self, wheel_base_m: float, wheel_diameter_m: float, ticks_per_rev: float, *,
                 tau_s: float = 0.06, dead_s: float = 0.0, floor_s: float = 0.0, window: int = 100,
                 step_s: float = 0.005) -> None:
        self.wheel_base = wheel_base_m
        self.m_per_tick = math.pi * wheel_diameter_m / ticks_per_rev
        self.tau_s = tau_s
        self.dead_s = dead_s
        self.floor_s = floor_s
        self.step_s = step_s
        self._offsets: deque[float] = deque(maxlen=window)
        self._cmd_t: list[float] = []  # host send times, ascending
        self._cmd: list[tuple[float, float]] = []  # (left, right) mm/s
        self._last: dict[str, object] | None = None
        self._prev: dict[str, object] | None = None
        self.latencies: list[float] = []  # each frame's estimated latency, s

    # --- what the host sees ---------------------------------------------------------------------------
    def on_command(self, t_host: float, left_mm_s: float, right_mm_s: float) -> None:
        """A wheel-speed COMMAND (HOST mode) the host sent at host time t_host (s)."""
        self._cmd_t.append(t_host)
        self._cmd.append((float(left_mm_s), float(right_mm_s)))

    def on_telemetry(self, frame: dict[str, object], t_arrival: float) -> None:
        """A TELEMETRY frame (protocol/messages.py fields) that arrived at host time t_arrival (s)."""
        tick_s = int(frame["tick_ms"]) / 1000.0  # type: ignore[call-overload]
        offset = t_arrival - tick_s
        self._offsets.append(offset)
        self.latencies.append(offset - min(self._offsets) + self.floor_s)
        if self._last is not None and int(frame["tick_ms"]) <= int(self._last["tick_ms"]):  # type: ignore[call-overload]
            return  # older than what we have: the latency counts, the state does not
        self._prev, self._last = self._last, frame

    @property
    def latency_s(self) -> float | None:
        """The latest frame's estimated one-way latency (s)."""
        return self.latencies[-1] if self.latencies else None

    def robot_time(self, t_host: float) -> float:
        """The robot's clock (s) at host time t_host: host time minus (clock offset)."""
        return t_host - (min(self._offsets) - self.floor_s)

    # --- poses ----------------------------------------------------------------------------------------
    def raw_pose(self) -> tuple[float, float, float] | None:
        """The last frame's odometry (m, m, rad): where the robot was, late."""
        return None if self._last is None else odometry_pose(self._last)

    def wheel_speeds(self) -> tuple[float, float]:
        """Wheel speeds (m/s) from the last two frames' encoder counts; the set-points if only one."""
        last, prev = self._last, self._prev
        assert last is not None
        dt = (int(last["tick_ms"]) - int(prev["tick_ms"])) / 1000.0 if prev is not None else 0.0  # type: ignore
        if prev is None or dt <= 0.0:
            return int(last["sp_l"]) / 1000.0, int(last["sp_r"]) / 1000.0  # type: ignore[call-overload]
        k = self.m_per_tick / dt
        return ((int(last["enc_l"]) - int(prev["enc_l"])) * k,  # type: ignore[call-overload]
                (int(last["enc_r"]) - int(prev["enc_r"])) * k)  # type: ignore[call-overload]

    def setpoint_at(self, t_robot: float, fallback: tuple[float, float]) -> tuple[float, float]:
        """The set-point (m/s) in force at robot time t_robot: the last command sent by then, after the dead time."""
        t_host = t_robot - self.dead_s + (min(self._offsets) - self.floor_s)
        i = bisect.bisect_right(self._cmd_t, t_host) - 1
        if i < 0:
            return fallback
        left, right = self._cmd[i]
        return left / 1000.0, right / 1000.0

    def predict(self, t_host: float) -> tuple[float, float, float] | None:
        """The robot's pose (m, m, rad, odometry frame) at host time t_host; None before the first frame."""
        last = self._last
        if last is None:
            return None
        x, y, phi = odometry_pose(last)
        vl, vr = self.wheel_speeds()
        t = int(last["tick_ms"]) / 1000.0  # type: ignore[call-overload]
        end = self.robot_time(t_host)
        sp_fallback = (int(last["sp_l"]) / 1000.0, int(last["sp_r"]) / 1000.0)  # type: ignore[call-overload]
        while t < end - 1e-9:
            h = min(self.step_s, end - t)
            spl, spr = self.setpoint_at(t, sp_fallback)
            a = 1.0 - math.exp(-h / self.tau_s)
            vl2, vr2 = vl + (spl - vl) * a, vr + (spr - vr) * a
            v = 0.25 * (vl + vr + vl2 + vr2)
            w = 0.5 * ((vr - vl) + (vr2 - vl2)) / self.wheel_base
            mid = phi + 0.5 * w * h
            x += v * h * math.cos(mid)
            y += v * h * math.sin(mid)
            phi += w * h
            vl, vr, t = vl2, vr2, t + h
        return x, y, phi

    def forget_before(self, t_host: float) -> None:
        """Drop commands older than the last one in force at t_host (keeps memory bounded)."""
        i = bisect.bisect_right(self._cmd_t, t_host) - 1
        if i > 0:
            del self._cmd_t[:i]
            del self._cmd[:i]


def odometry_pose(frame: dict[str, object]) -> tuple[float, float, float]:
    """A TELEMETRY frame's odometry as (m, m, rad), heading in (-pi, pi]."""
    turns = int(frame["odo_heading"]) / TURN  # type: ignore[call-overload]
    turns -= round(turns)
    return (int(frame["odo_x"]) / 1e6, int(frame["odo_y"]) / 1e6,  # type: ignore[call-overload]
            2.0 * math.pi * turns)
