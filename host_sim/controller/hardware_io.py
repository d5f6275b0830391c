"""The robot's electrical interface as the host sees it, and the constants it shares with the firmware.

Every controller takes a control cycle's readings (a `Sense`: what a HW_SENSE frame
carries) and returns its outputs (an `Actuate`: a HW_ACTUATE).  Robots (SimRobot or any
plant) and controllers (SIL, PIL, replay) meet here and nowhere else, so this module
imports no physics and no firmware runtime.  The firmware's own numbers (control period,
tick mask, rule-set names, the HAL's full-scale current) are taken from the firmware
(docs/firmware.md); how its current references reach each drive: docs/motors.md "Drives".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from firmware.config import CURRENT_FULL_SCALE_MA, DEFAULT_CYCLE_MS
from firmware.fuzzy import RULE_SET_NAMES
from firmware.hal import TICK_MASK
from host_sim.physics.params import DRIVE_UNITS, RobotParams
from protocol import messages as M
from protocol.framing import FrameEncoder

CYCLE_S = DEFAULT_CYCLE_MS / 1000.0  # s, the firmware's control period
RULE_SETS = {name: index for index, name in enumerate(RULE_SET_NAMES)}  # "first" -> 0, "refined" -> 1

__all__ = ["CYCLE_S", "RULE_SETS", "TICK_MASK", "Actuate", "IdleController", "Sense", "setup_frames", "hal_duty",
           "top_speed", "firmware_command", "firmware_drive_block", "FIRMWARE_DRIVES"]


@dataclass
class Sense:
    """One cycle's readings: what a HW_SENSE frame carries."""

    tick_ms: int  # the board's clock, modulo TICK_MASK + 1
    adc_off: list[int]  # IR ADC counts, emitters off (ambient), S1..S8
    adc_on: list[int]  # IR ADC counts, emitters on
    enc_l: int  # cumulative encoder ticks
    enc_r: int
    vbat_mv: int


@dataclass
class Actuate:
    """One cycle's outputs: what a HW_ACTUATE frame carries."""

    i_left_ma: int  # current references
    i_right_ma: int
    emitter_pct: int  # IR emitter pulse width, the light power L


DUTY_STEPS = 65535  # the RP2040 HAL's PWM register (duty_u16) at full duty
# The drives the firmware's current references can run (docs/motors.md "Drives"): every one; a wheel_speed
# robot's board takes the HAL's duty as a fraction of its top speed (firmware_command).
FIRMWARE_DRIVES = ("current", "voltage", "duty", "wheel_speed")


def hal_duty(ma: int) -> float:
    """The signed PWM duty (fraction) the RP2040 HAL writes for a current reference of ma (firmware/hal_rp2040.py
    `_drive`): |ma| / CURRENT_FULL_SCALE_MA in 16-bit steps, clipped to full duty
    (tests/test_drives.py::test_the_hal_duty_is_the_rp2040_hals)."""
    mag = abs(int(ma))
    steps = min(mag * DUTY_STEPS // CURRENT_FULL_SCALE_MA, DUTY_STEPS)
    return (-steps if ma < 0 else steps) / DUTY_STEPS


def top_speed(p: RobotParams) -> float:
    """The no-load wheel speed (rad/s) robot p's bridge gives at full duty: the nominal battery_voltage over
    the back-EMF constant through the gear (torque_constant * gear_ratio), where e = k_e N w meets V_s."""
    return p.battery_voltage / (p.torque_constant * p.gear_ratio)


def firmware_command(p: RobotParams) -> Callable[[int], float]:
    """How a firmware current reference (mA) reaches robot p's drive, in the drive's unit (params.DRIVE_UNITS):
    a current regulator takes it in A; an H-bridge takes the duty the HAL writes (duty drive), or that duty
    times the battery voltage (voltage drive); a set-point robot's board takes that duty as a fraction of its
    top speed (wheel_speed drive: top_speed), so the firmware's wheel PI sits outside the robot's speed loop."""
    kind = p.drive_kind
    if kind == "current":
        return lambda ma: ma / 1000.0
    if kind == "duty":
        return hal_duty
    if kind == "voltage":
        volts = p.battery_voltage
        return lambda ma: hal_duty(ma) * volts
    if kind == "wheel_speed":
        speed = top_speed(p)
        return lambda ma: hal_duty(ma) * speed
    raise ValueError(f"drive '{kind}': not one the firmware's HAL can drive")


def firmware_drive_block(p: RobotParams) -> dict[str, object]:
    """The recording sidecar's drive block for the firmware's commands on robot p (docs/recordings.md "The drive
    block"): the HAL's full scale in the firmware's unit (mA) and what it gives in the drive's unit."""
    kind = p.drive_kind
    return {"kind": kind, "unit": DRIVE_UNITS[kind], "source_unit": "mA", "full_scale": CURRENT_FULL_SCALE_MA,
            "at_full_scale": firmware_command(p)(CURRENT_FULL_SCALE_MA)}


FIRMWARE_IR_PAIRS = 8  # the firmware's HAL reads eight phototransistors a cycle (Sense.adc_on)


def geometry_from_params(wheel_radius_m: float, half_axle_m: float, ticks_per_rev: int) -> tuple[int, int, int]:
    """The firmware's geometry parameters (wheel_diameter_um, wheel_base_um, ticks_per_rev) of a
    robot given as RobotParams does; protocol.messages.geometry_frames turns them into PARAM_SETs."""
    return round(2 * wheel_radius_m * 1e6), round(2 * half_axle_m * 1e6), int(ticks_per_rev)


def firmware_geometry(p: RobotParams) -> tuple[int, int, int]:
    """(wheel_diameter_um, wheel_base_um, ticks_per_rev) of the robot p describes, as its firmware needs them.

    The firmware knows one wheel diameter and one encoder: those of the mean wheel, when a fitted
    parameter file gives the two wheels different radii or encoders."""
    radius = p.wheel_radius + 0.5 * (p.wheel_radius_delta_l + p.wheel_radius_delta_r)
    ticks = p.ticks_per_rev + 0.5 * (p.ticks_per_rev_delta_l + p.ticks_per_rev_delta_r)
    return geometry_from_params(radius, p.half_axle, round(ticks))


def setup_frames(rule_set: int, mode: int = M.MODE_AUTONOMOUS, params: RobotParams | None = None) -> list[bytes]:
    """What the host says to the firmware before its first cycle: the robot's geometry (when the host
    knows the robot's parameters), the rule set, then the mode.  ValueError: a geometry the firmware
    cannot hold (outside its parameter ranges)."""
    if params is not None and len(params.ir_bearings) != FIRMWARE_IR_PAIRS:
        raise ValueError(f"the firmware reads {FIRMWARE_IR_PAIRS} IR pairs, and this robot has "
                         f"{len(params.ir_bearings)} (ir_bearings): it replays and is diagnosed, it cannot run the firmware")
    enc = FrameEncoder()
    frames = M.geometry_frames(enc, *firmware_geometry(params)) if params is not None else []
    return frames + [
        enc.encode(M.PARAM_SET, M.pack_payload(M.PARAM_SET, {"param": M.param_by_name("rule_set")[0],
                                                               "value": rule_set})),
        enc.encode(M.COMMAND, M.pack_payload(M.COMMAND, {"mode": mode, "left": 0, "right": 0})),
    ]


def stall_guard_off() -> bytes:
    """The PARAM_SET that leaves the paper's explorer alone: the firmware's stall guard off (stall_ms = 0)."""
    return FrameEncoder().encode(M.PARAM_SET, M.pack_payload(M.PARAM_SET, {"param": M.param_by_name("stall_ms")[0],
                                                                           "value": 0}))


class IdleController:
    """Zero currents, emitters off: a robot that is switched off."""

    name = "idle"

    def cycle(self, s: Sense) -> Actuate:
        return Actuate(0, 0, 0)

    def close(self) -> None:
        pass
