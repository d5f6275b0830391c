"""What a recording's cmd_l and cmd_r hold: the sidecar's "drive" block (docs/recordings.md, "The drive").

A sidecar without the block is a current drive in A (every recording the firmware makes).
"""
from __future__ import annotations

# The drive's canonical unit of a command: the unit cmd_l and cmd_r hold.
UNITS = {"current": "A", "voltage": "V", "duty": "fraction", "wheel_speed": "rad/s"}
DEFAULT = {"kind": "current", "unit": "A"}
# The drive's parameters a robot file may hold (the contract's names), with their choices (None: a number >= 0).
DRIVE_KEYS: dict[str, tuple[str, ...] | None] = {
    "drive": tuple(UNITS), "pwm_decay": ("coast", "brake"), "driver_deadband": None, "dead_time": None,
    "pwm_frequency": None, "motor_inductance": None, "speed_kp": None, "speed_ki": None, "speed_loop_period": None}


def without_drive(robot: dict[str, object]) -> dict[str, object]:
    """A robot block without its drive's parameters: what a reader that runs no drive (a plot) needs."""
    return {k: v for k, v in robot.items() if k not in DRIVE_KEYS}


def drive_of(meta: dict[str, object]) -> dict[str, object]:
    """The sidecar's drive block, the default where it has none."""
    block = meta.get("drive")
    return dict(block) if isinstance(block, dict) else dict(DEFAULT)


def drive_problem(meta: dict[str, object]) -> str | None:
    """Why the sidecar's drive block cannot be read, or disagrees with its robot's `drive`; None if fine."""
    if "drive" not in meta:
        return None
    block = meta["drive"]
    if not isinstance(block, dict):
        return "'drive' must be an object with 'kind' and 'unit'"
    kind, unit = block.get("kind"), block.get("unit")
    if kind not in UNITS:
        return f"drive kind {kind!r} is not one of {', '.join(UNITS)}"
    if unit != UNITS[str(kind)]:
        return f"drive unit {unit!r}: a {kind} drive's commands are recorded in {UNITS[str(kind)]}"
    robot = meta.get("robot") if isinstance(meta.get("robot"), dict) else {}
    said = robot.get("drive", "current")  # type: ignore[union-attr]
    if said != kind:
        return f"the robot's parameters say drive {said!r}, the drive block says {kind!r}"
    return None
