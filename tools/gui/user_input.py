"""The user's orders: arrow keys or a joystick / gamepad, as two wheel speeds (mm/s).

Everything comes from events, never from polling the devices, so posted events (the offscreen
tests, where no real joystick exists) drive the robot exactly as a device does.  See docs/gui.md.
"""
from __future__ import annotations

from typing import Any

import pygame

DEADZONE = 0.12  # stick travel ignored around the centre
TURN_SHARE = 0.6  # full turn input = this fraction of max_speed on each wheel


class UserControl:
    """The arrows from KEYDOWN / KEYUP, the sticks from JOYAXISMOTION, the d-pad from JOYHATMOTION.

    Joysticks come and go while the application runs (JOYDEVICEADDED / JOYDEVICEREMOVED).  Forward
    speed from up/down (or the left stick's Y, pushed up = forward), turning from left/right (stick X),
    mixed as a differential drive: left = v - w, right = v + w, each limited to max_speed.
    """

    def __init__(self, max_speed: int = 200) -> None:
        self.max_speed = max_speed
        self.arrows: set[int] = set()
        self.axes: dict[tuple[int, int], float] = {}  # (instance_id, axis) -> -1..1
        self.hats: dict[int, tuple[int, int]] = {}
        self.joysticks: dict[int, Any] = {}  # instance_id -> pygame Joystick
        self.last_device = "keyboard"

    def handle(self, event: pygame.event.Event) -> bool:
        """Take the event if it is a user order or a device coming or going; True if taken."""
        t = event.type
        if t in (pygame.KEYDOWN, pygame.KEYUP) and event.key in (pygame.K_UP, pygame.K_DOWN,
                                                                 pygame.K_LEFT, pygame.K_RIGHT):
            (self.arrows.add if t == pygame.KEYDOWN else self.arrows.discard)(event.key)
            self.last_device = "keyboard"
            return True
        if t == pygame.JOYAXISMOTION:
            self.axes[(event.instance_id, event.axis)] = float(event.value)
            self.last_device = self._name(event.instance_id)
            return True
        if t == pygame.JOYHATMOTION:
            self.hats[event.instance_id] = tuple(event.value)  # type: ignore[assignment]
            self.last_device = self._name(event.instance_id)
            return True
        if t == pygame.JOYDEVICEADDED:
            try:
                joy = pygame.joystick.Joystick(event.device_index)
            except pygame.error as exc:  # unplugged again already, or no driver
                self.last_device = f"joystick {event.device_index} could not be opened: {exc}"
                return True
            self.joysticks[joy.get_instance_id()] = joy
            self.last_device = joy.get_name()
            return True
        if t == pygame.JOYDEVICEREMOVED:
            self.joysticks.pop(event.instance_id, None)
            self.axes = {k: v for k, v in self.axes.items() if k[0] != event.instance_id}
            self.hats.pop(event.instance_id, None)
            return True
        return False

    def _name(self, instance_id: int) -> str:
        joy = self.joysticks.get(instance_id)
        return joy.get_name() if joy is not None else f"joystick {instance_id}"

    def stick(self) -> tuple[float, float]:
        """(forward, turn left) in -1..1 from the arrows, else the d-pad, else the sticks."""
        if self.arrows:
            up_down = (pygame.K_UP in self.arrows) - (pygame.K_DOWN in self.arrows)
            left_right = (pygame.K_LEFT in self.arrows) - (pygame.K_RIGHT in self.arrows)
            return float(up_down), float(left_right)
        for hx, hy in self.hats.values():
            if hx or hy:
                return float(hy), float(-hx)
        fwd = turn = 0.0
        for (_jid, axis), value in self.axes.items():
            if abs(value) < DEADZONE:
                continue
            if axis == 1:
                fwd = -value  # SDL: stick pushed up is negative
            elif axis == 0:
                turn = -value
        return fwd, turn

    def wheels(self) -> tuple[int, int]:
        """Wheel-speed orders, mm/s: what a HOST-mode COMMAND carries."""
        fwd, turn = self.stick()
        v = fwd * self.max_speed
        w = turn * TURN_SHARE * self.max_speed
        lim = self.max_speed
        return (int(round(max(-lim, min(lim, v - w)))), int(round(max(-lim, min(lim, v + w)))))

    def device(self) -> str:
        n = len(self.joysticks)
        return f"{self.last_device}; {n} joystick{'s' if n != 1 else ''} connected"
