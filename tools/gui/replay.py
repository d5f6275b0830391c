"""The replay panel's state: a recording loaded, the slider's time, playing, and its diagnosis.

The diagnosis (host_sim.diagnosis.diagnose) runs in a worker thread so that the window's loop goes on.
What the window draws of it is tools/gui/replay_panel.py.  See docs/gui.md, "Replay and diagnosis".
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from host_sim.controller.hardware_io import firmware_geometry
from host_sim.diagnosis import Diagnosis, DiagnosisError, diagnose
from host_sim.physics.params import RobotParams, params_from_dict
from host_sim.physics.world import World, world_from_dict
from host_sim.recordings.recording import Recording, load_recording, sidecar_path

Pose = tuple[float, float, float]
SCRUB_STEP_S = 1.0  # PgUp / PgDn move the slider this far


@dataclass
class Replayed:
    """A recording as the panel shows it: one row per control cycle."""

    path: Path
    rec: Recording
    params: RobotParams  # the sidecar's robot (else the window's): the twin the diagnosis judges
    world: World | None  # the sidecar's room: what the diagnosis judges the IR sensors against
    pose: np.ndarray  # (n, 3) the pose drawn: the tracker's, else the odometry placed at the start
    pose_source: str
    ir: np.ndarray  # (n, 8) reflected counts: emitters on minus ambient, as the window's bars
    wheels: np.ndarray  # (n, 2) mm/s, from the encoders
    setpoints: np.ndarray | None  # (n, 2) mm/s the firmware's controller asked of its wheel loops
    commands: np.ndarray  # (n, 2) mA, the current references the firmware set

    @property
    def t(self) -> np.ndarray:
        return self.rec.t

    def index(self, t: float) -> int:
        """The row shown at time t: the last one at or before it."""
        return int(np.clip(np.searchsorted(self.rec.t, t, side="right") - 1, 0, len(self.rec.t) - 1))


def load_replay(path: Path, params: RobotParams, start: Pose) -> Replayed:
    """Load and prepare a recording (RecordingError, ParamsError or WorldError, all ValueError, if it is bad).

    params and start are the window's, used where the sidecar names no robot or room."""
    rec = load_recording(path)
    robot = rec.meta.get("robot")
    if isinstance(robot, dict) and robot:
        params = params_from_dict(robot, f"{path} (sidecar robot)")
    world = world_from_dict(rec.meta["world"], f"{path} (sidecar world)") if isinstance(rec.meta.get("world"), dict) \
        else None
    if len(rec) == 0:
        raise ValueError(f"{path}: no rows to replay")
    pose, source = recorded_pose(rec, params, world.start if world is not None else start)
    diameter_um, _base, ticks = firmware_geometry(params)
    dt = np.diff(rec.t, prepend=rec.t[0] - rec.sample_period)
    wheels = np.diff(rec.enc, axis=0, prepend=rec.enc[:1]) / dt[:, None] * math.pi * diameter_um / 1000.0 / ticks
    setpoints = 1000.0 * rec.firmware[:, 1:3] if rec.firmware is not None else None
    ir = np.clip(rec.ir_on - rec.ir_amb, 0, None)
    return Replayed(path, rec, params, world, pose, source, ir, wheels, setpoints, 1000.0 * rec.cmd)


def recorded_pose(rec: Recording, params: RobotParams, start: Pose) -> tuple[np.ndarray, str]:
    """The tracker's pose; without one the firmware's odometry, else the encoders integrated here (both from
    the start pose, as the window places the real robot)."""
    if rec.pose is not None:
        return rec.pose, "tracker"
    if rec.firmware is not None:
        odo, source = rec.firmware[:, 3:6], "the firmware's odometry (no tracker), from the start pose"
    else:
        odo, source = integrate_encoders(rec.enc, params), "the encoders integrated here (no tracker, no odometry)"
    c, s = math.cos(start[2]), math.sin(start[2])
    pose = np.column_stack([start[0] + c * odo[:, 0] - s * odo[:, 1], start[1] + s * odo[:, 0] + c * odo[:, 1],
                            start[2] + odo[:, 2]])
    return pose, source


def integrate_encoders(enc: np.ndarray, params: RobotParams) -> np.ndarray:
    """(n, 3) dead reckoning from the first row's encoders, with the geometry the firmware uses."""
    diameter_um, base_um, ticks = firmware_geometry(params)
    step = np.diff(enc, axis=0, prepend=enc[:1]) * math.pi * diameter_um / 1e6 / ticks  # (n, 2) m per wheel
    ds, dphi = step.mean(axis=1), (step[:, 1] - step[:, 0]) / (base_um / 1e6)
    phi = np.cumsum(dphi)
    mid = phi - dphi / 2
    return np.column_stack([np.cumsum(ds * np.cos(mid)), np.cumsum(ds * np.sin(mid)), phi])


class DiagnosisJob:
    """host_sim.diagnosis.diagnose of one recording in a worker thread (one process: the same verdict and
    figures as `twinbot diagnose --workers 1`); the window polls it each frame."""

    def __init__(self, replayed: Replayed) -> None:
        self.replayed = replayed
        self.started = time.monotonic()
        self.finished: float | None = None
        self.stage = "starting"
        self.result: Diagnosis | None = None
        self.error: str | None = None
        self.announced = False
        self.thread = threading.Thread(target=self._run, name="twinbot-gui-diagnose", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        r = self.replayed
        try:
            self.result = diagnose(r.rec, r.params, r.world, progress=self._progress, workers=1)
        except DiagnosisError as exc:  # too short, too still: said plainly, as the command says it
            self.error = f"not diagnosed: {exc}"
        except Exception as exc:  # noqa: BLE001 - the window says it and runs on
            self.error = f"the diagnosis failed: {type(exc).__name__}: {exc}"
        finally:
            self.finished = time.monotonic()

    def _progress(self, stage: str) -> None:
        self.stage = stage

    @property
    def running(self) -> bool:
        return self.finished is None

    def elapsed(self) -> float:
        return (self.finished if self.finished is not None else time.monotonic()) - self.started

    def located(self) -> list[tuple[str, list[tuple[float, float]]]]:
        """(channel, its time spans in s) of each mismatch the diagnosis located in the recording."""
        if self.result is None:
            return []
        return [(str(item["channel"]), [(float(a), float(b)) for a, b in item["spans"]]) for item in self.result.located]

    def verdict(self) -> str:
        """One line: the verdict and the effects named, or why there is none."""
        if self.running:
            return f"diagnosing... {self.elapsed():.0f} s ({self.stage})"
        if self.result is None:
            return str(self.error)
        d = self.result
        names = [e["name"] + (f" ({e['wheel']} wheel)" if "wheel" in e else f" (S{e['sensor'] + 1})" if "sensor" in e
                              else "") for e in d.effects]
        return f"diagnosis: {d.verdict}" + (f": {', '.join(names)}" if names else "") + f" ({self.elapsed():.1f} s)"


class Replay:
    """The panel: the recording shown (None: closed), the slider's time, playing or not, the diagnosis."""

    def __init__(self, first: Path | None = None) -> None:
        self.first = first  # `twinbot gui --replay FILE`: the first recording `e` loads
        self.shown: Replayed | None = None
        self.time = 0.0
        self.playing = False
        self.job: DiagnosisJob | None = None

    @property
    def open(self) -> bool:
        return self.shown is not None

    def candidates(self, folder: Path) -> list[Path]:
        """The --replay file, then the recordings in the folder (those with a sidecar), newest first."""
        found = sorted((p for p in folder.glob("*.csv") if sidecar_path(p).is_file()),
                       key=lambda p: p.stat().st_mtime, reverse=True)
        return list(dict.fromkeys([*([self.first] if self.first is not None else []), *found]))

    def next_file(self, folder: Path) -> Path | None:
        """The candidate after the one shown (the first when none is, or after the last)."""
        files = self.candidates(folder)
        if not files:
            return None
        here = self.shown.path if self.shown is not None else None
        return files[(files.index(here) + 1) % len(files)] if here in files else files[0]

    def load(self, path: Path, params: RobotParams, start: Pose) -> str:
        """Show the recording at path; a bad one leaves the panel as it was.  Returns what to say."""
        try:
            shown = load_replay(path, params, start)
        except (OSError, ValueError) as exc:
            return f"replay: not loaded: {exc}"
        self.shown, self.time, self.playing, self.job = shown, float(shown.t[0]), False, None
        t = shown.t
        return (f"replay: {path.name}, {t[-1] - t[0]:.1f} s, {len(t)} rows; pose: {shown.pose_source} "
                f"(drag the slider; d diagnoses it)")

    def close(self) -> None:
        self.shown, self.playing, self.job = None, False, None

    def seek(self, t: float) -> None:
        if self.shown is not None:
            self.time = float(np.clip(t, self.shown.t[0], self.shown.t[-1]))

    def advance(self, wall_dt: float, speed: float) -> None:
        """Playing: the slider runs at the speed factor, and stops at the end."""
        if self.shown is not None and self.playing:
            self.seek(self.time + wall_dt * speed)
            self.playing = self.time < self.shown.t[-1]

    def diagnose(self) -> str:
        if self.shown is None:
            return "nothing to diagnose: load a recording first (e, or drop a file on the window)"
        if self.job is not None and self.job.running:
            return "diagnosing already: the verdict shows when it is done"
        self.job = DiagnosisJob(self.shown)
        return f"diagnosing {self.shown.path.name} in the background (the window runs on)"

    def finished(self) -> str | None:
        """The diagnosis's verdict, once, when it is done."""
        job = self.job
        if job is None or job.running or job.announced:
            return None
        job.announced = True
        return job.verdict()
