"""Pictures of worlds and runs (matplotlib, no display needed; docs/worlds.md)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np


def _pyplot():  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(plt, fig, path: str | Path) -> Path:  # type: ignore[no-untyped-def]
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_world(ax, world) -> None:  # type: ignore[no-untyped-def]
    for x1, y1, x2, y2 in world.segments:
        ax.plot([x1, x2], [y1, y2], color="0.15", lw=2.2, solid_capstyle="round")
    for poly in world.polygons:
        ax.fill(poly[:, 0], poly[:, 1], color="0.75", zorder=0)
    for lamp in world.lamps:
        ax.plot(lamp.x, lamp.y, marker="*", color="goldenrod", ms=12)
    ax.set_aspect("equal")
    ax.set_xlim(-0.05, world.size[0] + 0.05)
    ax.set_ylim(-0.05, world.size[1] + 0.05)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def draw_run(ax, run, body_radius: float, color: str = "tab:blue", label: str | None = None,  # type: ignore[no-untyped-def]
             linestyle: object = "-") -> None:
    pose = run.pose
    if not len(pose):
        return
    ax.plot(pose[:, 0], pose[:, 1], color=color, lw=1.0, label=label, linestyle=linestyle)
    x, y, phi = pose[0]
    ax.add_patch(_disc(x, y, body_radius, "tab:green"))
    x, y, phi = pose[-1]
    ax.add_patch(_disc(x, y, body_radius, color))
    ax.arrow(x, y, body_radius * math.cos(phi), body_radius * math.sin(phi), width=0.004, color="k")


def _disc(x: float, y: float, r: float, color: str):  # type: ignore[no-untyped-def]
    from matplotlib.patches import Circle

    return Circle((x, y), r, fill=False, color=color, lw=1.5)


def save_runs(path: str | Path, world, runs: Sequence[object], titles: Sequence[str], body_radius: float,  # type: ignore[no-untyped-def]
              suptitle: str = "") -> Path:
    """One panel per run, side by side (or 2 x 2 for four)."""
    plt = _pyplot()
    n = len(runs)
    cols = 2 if n == 4 else n
    rows = 2 if n == 4 else 1
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.4 * rows), squeeze=False)
    for ax, run, title in zip(axes.flat, runs, titles):
        draw_world(ax, world)
        draw_run(ax, run, body_radius)
        ax.set_title(title, fontsize=10)
    if suptitle:
        fig.suptitle(suptitle)
    return _save(plt, fig, path)


def save_coverage(path: str | Path, runs: Sequence[object], labels: Sequence[str]) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for run, label in zip(runs, labels):
        ax.plot(run.t, 100 * np.asarray(run.coverage), label=label)  # type: ignore[attr-defined]
    ax.axhline(90, color="0.6", ls="--", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("free area covered (%)")
    ax.set_ylim(0, 100)
    ax.legend()
    ax.grid(alpha=0.3)
    return _save(plt, fig, path)


def save_pairs(path: str | Path, world, pairs: Sequence[tuple[object, object]], titles: Sequence[str],  # type: ignore[no-untyped-def]
               body_radius: float, suptitle: str = "", labels: tuple[str, str] = ("run A", "run B")) -> Path:
    """One panel per pair of runs, the two routes drawn over each other (B dashed)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(pairs), figsize=(5.6 * len(pairs), 4.8), squeeze=False)
    for ax, (a, b), title in zip(axes.flat, pairs, titles):
        draw_world(ax, world)
        draw_run(ax, a, body_radius, "tab:blue", labels[0])
        draw_run(ax, b, body_radius, "tab:orange", labels[1], linestyle=(0, (4, 3)))  # dashed: B over A stays visible
        ax.set_title(title, fontsize=10)
        ax.legend(loc="lower right", fontsize=8)
    if suptitle:
        fig.suptitle(suptitle)
    return _save(plt, fig, path)


def wheel_speeds(rec, params) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n - 1, 2) wheel rim speeds in m/s from a recording's encoder counts (differences between rows)."""
    dt = np.diff(rec.t)[:, None]
    return np.diff(rec.enc, axis=0) * (2 * math.pi / params.ticks_per_rev) * params.wheel_radius / dt


# How the commands of each drive are drawn (the sidecar's drive block; docs/recordings.md): label, scale.
COMMAND_AXES = {"current": ("current reference (mA)", 1000.0), "voltage": ("voltage command (V)", 1.0),
                "duty": ("duty (%)", 100.0), "wheel_speed": ("wheel-speed set-point (rad/s)", 1.0)}


def save_recording(path: str | Path, rec, params, world=None, replayed=None) -> Path:  # type: ignore[no-untyped-def]
    """A recording at a glance: trajectory (the tracker's, else the firmware's odometry), wheel commands,
    encoder speeds, battery, IR on and ambient.

    replayed: a host_sim.recordings.replay.ReplayResult drawn beside the recorded trajectory.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(3, 2, figsize=(12, 11))
    (traj, cmd), (speed, vbat), (ir_on, ir_amb) = axes
    _draw_trajectory(traj, rec, world, replayed)
    kind = str((rec.meta.get("drive") or {}).get("kind", "current"))
    label, scale = COMMAND_AXES.get(kind, COMMAND_AXES["current"])
    for k, side in enumerate(("left", "right")):
        cmd.plot(rec.t, scale * rec.cmd[:, k], lw=0.9, label=side)
    cmd.set_ylabel(label)
    cmd.set_title("wheel commands")
    if len(rec) > 1:
        v = wheel_speeds(rec, params)
        for k, side in enumerate(("left", "right")):
            speed.plot(rec.t[1:], 1000 * v[:, k], lw=0.9, label=side)
    speed.set_ylabel("wheel rim speed (mm/s)")
    speed.set_title("encoder speeds")
    if rec.battery_recorded:
        vbat.plot(rec.t, rec.vbat, color="tab:purple", lw=0.9)
    else:
        _absent(vbat, "no battery voltage in this recording")
    vbat.set_ylabel("battery (V)")
    vbat.set_title("battery")
    _draw_ir(ir_on, ir_amb, rec)
    for ax in (cmd, speed, vbat, ir_on, ir_amb):
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    for ax in (cmd, speed):
        ax.legend(fontsize=8)
    name = rec.path.name if rec.path is not None else "recording"
    fig.suptitle(f"{name}: {len(rec)} rows, {rec.t[-1] - rec.t[0]:.1f} s, source {rec.meta.get('source', '?')}"
                 if len(rec) else f"{name}: empty")
    return _save(plt, fig, path)


def _absent(ax, text: str) -> None:  # type: ignore[no-untyped-def]
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes)


def _draw_trajectory(traj, rec, world, replayed) -> None:  # type: ignore[no-untyped-def]
    """The tracker's pose (its rows with one), else the firmware's own odometry, else a word why not."""
    if world is not None:
        draw_world(traj, world)
    if rec.pose is not None:
        xy, title = rec.pose[:, :2], "trajectory (tracker)"
    elif rec.firmware is not None:
        xy, title = rec.firmware[:, 3:5], "trajectory (the firmware's odometry; no tracker)"
    else:
        _absent(traj, "no tracker pose nor odometry in this recording")
        traj.set_title("trajectory")
        return
    traj.plot(xy[:, 0], xy[:, 1], color="tab:blue", lw=1.0, label="recorded")
    first = np.flatnonzero(np.isfinite(xy).all(axis=1))
    if len(first):
        traj.plot(*xy[first[0]], "o", color="tab:green", label="start")
    if replayed is not None and rec.pose is not None:
        traj.plot(replayed.pose[:, 0], replayed.pose[:, 1], color="tab:red", lw=1.0, ls="--", label="twin, replayed")
    traj.legend(fontsize=8)
    traj.set_aspect("equal")
    traj.set_title(title)


def _draw_ir(ir_on, ir_amb, rec) -> None:  # type: ignore[no-untyped-def]
    """Each IR sensor's readings, emitters on and ambient; a word where the recording has none."""
    for ax, data, title, here in ((ir_on, rec.ir_on, "IR, emitters on", rec.n_ir > 0),
                                  (ir_amb, rec.ir_amb, "IR, ambient (emitters off)", rec.n_ir > 0 and rec.ambient_recorded)):
        if here:
            for i in range(data.shape[1]):
                ax.plot(rec.t, data[:, i], lw=0.7, label=f"S{i + 1}")
        else:
            _absent(ax, "no IR sensors in this recording" if not rec.n_ir else "no ambient readings in this recording")
        ax.set_ylabel("ADC counts")
        ax.set_title(title)
    if rec.n_ir:
        ir_on.legend(fontsize=7, ncol=4)
