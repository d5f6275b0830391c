"""What would tell two effects apart that explain a recording equally well.

Drive effects: both fitted twins run the identification manoeuvre, and the segment where they differ most
(as a z against what a recording resolves) is named.  IR effects: a sentence from the pair's physics
(IR_APART).  docs/diagnosis.md, "Equally good rivals".
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from host_sim.physics import effects as E
from host_sim.loops.excitation import CYCLE_S, ExcitedController, schedule
from host_sim.controller.hardware_io import CYCLE_S as PERIOD_S, RULE_SETS, TICK_MASK, Sense, firmware_command
from host_sim.physics.params import RobotParams
from host_sim.controller.sil import SilController
from host_sim.robot.batch import SUBSTEPS, BatchSim
from host_sim.physics.world import World

CURRENT_NOISE_A = 0.002  # what a recording resolves of a current reference (a few mA of loop jitter)
SPEED_NOISE_MS = 0.004  # m/s of the body's speed over one 40 ms period (1 mm tracker noise)
YAW_NOISE = 0.1  # rad/s of yaw rate over one period (0.3 deg tracker noise)
SEPARATION_MIN = 5.0  # z of a segment's difference that makes it decisive
OPEN_FLOOR = World(name="open floor", size=(6.0, 6.0), walls=[], start=(3.0, 3.0, 0.0))
COMMAND = "twinbot serial PORT --excite --record F.csv"
OTHER_DRIVES = ("a recording whose commands step between several sizes in both directions, each held until the "
                "wheels settle, would tell them apart")

# Sensor effects that look alike in one kind of data, and the data that separates them.
IR_APART = {
    frozenset({"ir_offset", "ambient_leakage"}): ("a change of ambient light (a lamp switched on and off, or the robot "
                                                  "turned towards a window)",
                                                  "leakage scales with the ambient, an offset does not"),
    frozenset({"ir_gain", "ir_misalignment"}): ("a wall seen from several angles (the robot turned in place in front "
                                                "of it)", "a misaligned sensor peaks off its nominal bearing, a weak one "
                                                          "only reads lower"),
    frozenset({"ir_gain", "ir_offset"}): ("a wall at several distances",
                                          "a gain scales the reflected light, an offset adds the same counts at every "
                                          "distance"),
    frozenset({"ir_latency", "ir_misalignment"}): ("the same wall passed slowly and fast",
                                                   "a latency shifts with the speed, a misalignment does not"),
}
IR_DEFAULT = ("the sensor's readings against a wall at several distances and angles", "")


@dataclass
class ManoeuvreRun:
    segment: np.ndarray  # (n,) segment name per control period
    cmd: np.ndarray  # (n, 2) A, the firmware's current references
    speed: np.ndarray  # (n,) m/s of C
    yaw_rate: np.ndarray  # (n,) rad/s


def run_manoeuvres(params: Sequence[RobotParams], cycles: float = 1.0) -> list[ManoeuvreRun]:
    """Each twin through the manoeuvre (its own firmware in the loop, HOST mode), noise-free, on an open floor,
    all in one BatchSim: a Simulation.run_fixed each, stepped together, so that telling one effect apart from
    its rivals costs one run's steps (tests/test_diagnosis_apart.py::test_twins_run_together_run_as_alone)."""
    controllers = [ExcitedController(SilController(RULE_SETS["refined"], params=p)) for p in params]
    commands = [firmware_command(p) for p in params]
    try:
        batch = BatchSim(OPEN_FLOOR, list(params), substeps=1, initial_emitter_pct=0.0)
        n_periods, dt = int(round(cycles * CYCLE_S / PERIOD_S)), PERIOD_S / SUBSTEPS
        n = len(params)
        t, pose, cmd = np.empty(n_periods), np.empty((n_periods, n, 3)), np.empty((n_periods, n, 2))
        i_ref = np.empty((n, 2))  # in each drive's unit (firmware_command), as SimRobot.actuate gives it
        for k in range(n_periods):
            t[k], pose[k] = batch.t, batch.pose
            on, off = batch.read_sensors()
            enc, vbat = batch.encoder_ticks().tolist(), np.asarray(batch.vbat).reshape(-1).tolist()
            tick = int(round(batch.t * 1000)) & TICK_MASK
            for j, controller in enumerate(controllers):
                a = controller.cycle(Sense(tick, off[j].tolist(), on[j].tolist(), enc[j][0], enc[j][1],
                                           int(round(vbat[j] * 1000))))
                cmd[k, j] = a.i_left_ma / 1000.0, a.i_right_ma / 1000.0
                i_ref[j] = commands[j](a.i_left_ma), commands[j](a.i_right_ma)
                batch.emitter_now = float(a.emitter_pct)  # one firmware, one schedule: every robot's the same
            for _ in range(SUBSTEPS):
                batch.substep(i_ref, dt)
    finally:
        for controller in controllers:
            controller.close()
    return [_run_of(t, pose[:, j], cmd[:, j]) for j in range(n)]


def _run_of(t: np.ndarray, pose: np.ndarray, cmd: np.ndarray) -> ManoeuvreRun:
    dt = np.diff(t)
    step = np.diff(pose, axis=0)
    speed = np.hypot(step[:, 0], step[:, 1]) / dt
    yaw = np.angle(np.exp(1j * step[:, 2])) / dt
    names = np.array([schedule(float(s))[0] for s in t[:-1]])
    return ManoeuvreRun(names, cmd[:-1], speed, yaw)


def run_manoeuvre(params: RobotParams, cycles: float = 1.0) -> ManoeuvreRun:
    """One twin through the manoeuvre (run_manoeuvres)."""
    return run_manoeuvres([params], cycles)[0]


def separation(a: ManoeuvreRun, b: ManoeuvreRun) -> list[tuple[str, float, str]]:
    """Per segment, best first: (segment, z of the difference, what differs, in words)."""
    out = []
    for name in dict.fromkeys(a.segment.tolist()):
        m = a.segment == name
        d_cmd = float(np.sqrt(np.mean((a.cmd[m] - b.cmd[m]) ** 2)))
        d_speed = float(np.sqrt(np.mean((a.speed[m] - b.speed[m]) ** 2)))
        d_yaw = float(np.sqrt(np.mean((a.yaw_rate[m] - b.yaw_rate[m]) ** 2)))
        scores = [(d_cmd / CURRENT_NOISE_A, f"current references differ by {1000 * d_cmd:.1f} mA RMS"),
                  (d_speed / SPEED_NOISE_MS, f"speeds differ by {1000 * d_speed:.1f} mm/s RMS"),
                  (d_yaw / YAW_NOISE, f"turn rates differ by {np.degrees(d_yaw):.1f} deg/s RMS")]
        level, words = max(scores)
        out.append((name, level * float(np.sqrt(m.sum())), words))
    return sorted(out, key=lambda r: -r[1])


def tell_apart(chosen: tuple[str, RobotParams], rival: tuple[str, RobotParams]) -> str:
    """A sentence: what data would separate the chosen effect from a rival that explains the data as well."""
    return tell_apart_all(chosen, [rival])[0]


def tell_apart_all(chosen: tuple[str, RobotParams], rivals: Sequence[tuple[str, RobotParams]]) -> list[str]:
    """tell_apart's sentence for each rival; the drive pairs' twins run the manoeuvre together (run_manoeuvres)."""
    name_a, p_a = chosen
    driven = [i for i, rival in enumerate(rivals) if not _sensor_pair(name_a, rival[0])]
    runs = run_manoeuvres([p_a] + [rivals[i][1] for i in driven]) if driven and p_a.drive_kind == "current" else []
    out = []
    for i, (name_b, _p_b) in enumerate(rivals):
        if i not in driven:
            pair = frozenset(n.split("(")[0] for n in (name_a, name_b))
            data, why = IR_APART.get(pair, IR_DEFAULT)
            out.append(f"{name_a} and {name_b} explain it equally well; {data} would tell them apart"
                       + (f": {why}" if why else ""))
        elif not runs:  # the manoeuvre runs this project's firmware, which commands currents
            out.append(f"{name_a} and {name_b} explain it equally well; {OTHER_DRIVES}")
        else:
            out.append(_drive_sentence(name_a, name_b, runs[0], runs[1 + driven.index(i)]))
    return out


def _sensor_pair(name_a: str, name_b: str) -> bool:
    return any(E.LIBRARY[n.split("(")[0]].kind == "sensor" for n in (name_a, name_b))


def _drive_sentence(name_a: str, name_b: str, run_a: ManoeuvreRun, run_b: ManoeuvreRun) -> str:
    segment, level, words = separation(run_a, run_b)[0]
    if level < SEPARATION_MIN:
        return (f"{name_a} and {name_b} explain it equally well, and the identification manoeuvre would not "
                f"tell them apart either (their twins differ most in its {segment}, z = {level:.1f} only)")
    return (f"{name_a} and {name_b} explain it equally well; the identification manoeuvre's {segment} would "
            f"tell them apart (their twins' {words} there, z = {level:.0f}): {COMMAND}")


__all__ = ["ManoeuvreRun", "run_manoeuvre", "run_manoeuvres", "separation", "tell_apart", "tell_apart_all"]
