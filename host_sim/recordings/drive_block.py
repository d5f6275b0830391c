"""What a recording's cmd_l and cmd_r hold: the sidecar's "drive" block (docs/recordings.md, "The drive").

A sidecar without the block is a current drive in A (every recording the firmware makes).
"""
from __future__ import annotations

# The drive's canonical unit of a command: the unit cmd_l and cmd_r hold.
UNITS = {"current": "A", "voltage": "V", "duty": "fraction", "wheel_speed": "rad/s"}
DEFAULT = {"kind": "current", "unit": "A"}


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
