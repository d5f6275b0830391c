"""The paper's sensor figures (7, 8, 10, 11, 12), drawn from the model (`twinbot plot sensor`).

PNGs in --out (default docs/figures): fig7_angle (the angle response), fig8_distance
(light against distance for three emitter powers), fig10_power (against emitter power),
fig11_3d_L27 and fig12_3d_L78 (against distance and angle at L = 27 % and 78 %).  Light
sensed is on - off = min(reflected, adc_max - ambient), without noise (docs/ir-sensor.md).
plot_worlds draws the built-in worlds (docs/worlds.md).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

DEFAULT_OUT = Path("docs/figures")
FIRMWARE_NEAR = (40, 700)  # firmware/fuzzy.py NEAR_LO, NEAR_HI: the obstacle membership ramp


def _pyplot() -> Any:
    # Imported here, not at the top: building the `twinbot` parser stays cheap.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def sensed(distance: Any, angle: Any, power_pct: Any, p: Any) -> np.ndarray:
    """on - off as the firmware sees it, noise-free: the reflected light clipped by the ADC ceiling."""
    from host_sim.sensors import ir_sensor

    return np.minimum(ir_sensor.response(distance, angle, power_pct, p), p.adc_max - p.ir_ambient)


def plot_angle(out: Path, p: Any) -> Path:
    from host_sim.sensors import ir_sensor

    plt = _pyplot()
    deg = np.linspace(-90, 90, 721)
    a = np.radians(deg)
    big, small, _w = ir_sensor.domes(a, p)
    blended = ir_sensor.angle_term(a, p)
    _t_big, t_total = ir_sensor.angle_target(a)
    lo, hi = p.ir_angle_blend
    fig, ax = plt.subplots(figsize=(7.5, 4.6), dpi=120)
    for sgn in (-1, 1):
        ax.axvspan(*sorted((sgn * math.degrees(lo), sgn * math.degrees(hi))), color="0.92", zorder=0,
                   label="blend zone" if sgn == 1 else None)
    marks = slice(None, None, 12)
    ax.plot(deg[marks], t_total[marks], "o", ms=3.5, color="0.45", label="target shape (white matte paper)")
    ax.plot(deg, big, "--", color="tab:blue", lw=1.4, label="big dome (5th degree, diffuse)")
    near = np.abs(a) <= hi + 0.15
    ax.plot(deg[near], small[near], ":", color="tab:red", lw=1.8, label="small dome (5th degree, specular)")
    ax.plot(deg, blended, color="k", lw=2.0, label="model A(angle): domes blended")
    ax.set_xlim(-90, 90)
    ax.set_ylim(0, 1.1)
    ax.set_xticks(range(-90, 91, 30))
    ax.set_xlabel("angle between the sensor axis and the wall normal (degrees)")
    ax.set_ylabel("relative response A")
    ax.set_title("Fig. 7 - angle response of the sensor")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower center", fontsize=8, framealpha=0.95)
    path = out / "fig7_angle.png"
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_distance(out: Path, p: Any, powers: tuple[float, ...] = (27, 50, 78)) -> Path:
    from host_sim.sensors import ir_sensor

    plt = _pyplot()
    x = np.linspace(0.0005, 0.30, 1200)
    ceiling = p.adc_max - p.ir_ambient
    fig, (ax, axl) = plt.subplots(1, 2, figsize=(11, 4.6), dpi=120)
    colors = ("tab:green", "tab:orange", "tab:blue")
    for L, col in zip(powers, colors):
        model = ir_sensor.response(x, 0.0, L, p)
        seen = np.minimum(model, ceiling)
        for a_ in (ax, axl):
            a_.plot(x * 100, seen, color=col, lw=2.0, label=f"L = {L:g} %")
            clipped = model > ceiling
            if clipped.any():
                a_.plot(x[clipped] * 100, model[clipped], color=col, lw=1.0, ls=(0, (4, 2)))
    far = p.ir_gain * ir_sensor.power_term(powers[-1], p) / x ** 2
    for a_ in (ax, axl):
        a_.plot(x * 100, far, color="0.3", lw=1.0, ls=":", label=f"C/x$^2$ (L = {powers[-1]:g} %)")
        a_.axhline(ceiling, color="tab:red", lw=1.0, label=f"ADC ceiling ({p.adc_max} - ambient {p.ir_ambient:g})")
        for level in FIRMWARE_NEAR:
            a_.axhline(level, color="0.55", lw=0.8, ls="-.")
        a_.set_xlabel("distance to the wall along the sensor axis (cm)")
        a_.grid(alpha=0.3, which="both")
    ax.set_xlim(0, 12)
    ax.set_ylim(0, 1.5 * ceiling)
    ax.set_ylabel("reflected light sensed, on - off (ADC counts)")
    ax.set_title("Fig. 8 - light sensed vs distance (0 degrees)")
    ax.text(11.8, FIRMWARE_NEAR[1] * 1.06, "firmware NEAR_HI", ha="right", fontsize=7, color="0.4")
    ax.legend(fontsize=8, loc="upper right")
    axl.set_xscale("log")
    axl.set_yscale("log")
    axl.set_xlim(0.1, 30)
    axl.set_ylim(3, 3e4)
    axl.set_title("the same, log-log: D x$^2$ near, C/x$^2$ far")
    axl.text(0.12, FIRMWARE_NEAR[0] * 1.1, "firmware NEAR_LO", fontsize=7, color="0.4")
    axl.text(0.12, FIRMWARE_NEAR[1] * 1.1, "firmware NEAR_HI", fontsize=7, color="0.4")
    axl.text(1.5, 4, "dashed: the model above the ceiling", fontsize=7, color="0.3")
    path = out / "fig8_distance.png"
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_power(out: Path, p: Any, distances_cm: tuple[float, ...] = (2, 3, 5, 8, 15)) -> Path:
    plt = _pyplot()
    L = np.linspace(0, 100, 401)
    fig, ax = plt.subplots(figsize=(7.5, 4.6), dpi=120)
    cmap = plt.get_cmap("viridis")
    for k, d in enumerate(distances_cm):
        ax.plot(L, sensed(d / 100, 0.0, L, p), color=cmap(k / max(1, len(distances_cm) - 1)), lw=2,
                label=f"{d:g} cm")
    ax.axvline(100 * p.ir_saturation, color="0.4", ls="--", lw=1)
    ax.text(100 * p.ir_saturation - 1, 150, f"emitter saturation {100 * p.ir_saturation:g} %", rotation=90,
            ha="right", va="bottom", fontsize=8, color="0.3")
    ax.axhline(p.adc_max - p.ir_ambient, color="tab:red", lw=1, label="ADC ceiling")
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 1.1 * (p.adc_max - p.ir_ambient))
    ax.set_xlabel("emitter power L, pulse width (%)")
    ax.set_ylabel("reflected light sensed, on - off (ADC counts)")
    ax.set_title("Fig. 10 - lighting power (wall at normal incidence)")
    ax.grid(alpha=0.3)
    ax.legend(title="distance", fontsize=8, loc="upper left")
    path = out / "fig10_power.png"
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_surface(out: Path, p: Any, power_pct: float, name: str, fig_no: int) -> Path:
    plt = _pyplot()
    d = np.concatenate([np.linspace(0.0005, 0.04, 110), np.linspace(0.0405, 0.10, 40)])
    deg = np.linspace(-90, 90, 91)
    D, A = np.meshgrid(d, deg)
    Z = sensed(D, np.radians(A), power_pct, p)
    fig = plt.figure(figsize=(8, 6), dpi=120)
    ax = fig.add_subplot(projection="3d")
    vmax = p.adc_max - p.ir_ambient
    surf = ax.plot_surface(D * 100, A, Z, cmap="jet", vmin=0, vmax=vmax, rstride=1, cstride=1, linewidth=0,
                           antialiased=True)
    ax.set_xlabel("distance (cm)")
    ax.set_ylabel("angle (degrees)")
    ax.set_zlabel("on - off (counts)")
    ax.set_zlim(0, vmax)
    ax.set_yticks(range(-90, 91, 45))
    ax.view_init(elev=30, azim=-120)
    ax.set_title(f"Fig. {fig_no} - sensor model, L = {power_pct:g} %\n"
                 f"dark red: saturated ADC; deep blue: lost in the noise", fontsize=10)
    fig.colorbar(surf, ax=ax, shrink=0.6, pad=0.1, label="ADC counts")
    path = out / name
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_sensor_figures(out_dir: str | Path = DEFAULT_OUT, p: Any = None) -> list[Path]:
    """Write the five figures; returns their paths."""
    from host_sim.physics.params import DEFAULT

    p = p or DEFAULT
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [plot_angle(out, p), plot_distance(out, p), plot_power(out, p),
            plot_surface(out, p, 27, "fig11_3d_L27.png", 11), plot_surface(out, p, 78, "fig12_3d_L78.png", 12)]


def plot_worlds(out_dir: str | Path = DEFAULT_OUT) -> Path:
    """The built-in worlds side by side (worlds.png): walls, start pose, lamps, the area of interest."""
    from host_sim.physics.world import BUILTIN_NAMES, builtin_world, draw_world

    plt = _pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, len(BUILTIN_NAMES), figsize=(15, 5.6), dpi=110, layout="constrained")
    for ax, name in zip(axes, BUILTIN_NAMES):
        world = builtin_world(name)
        free = world.free_cells(0.02, reachable=True)
        ax.imshow(free, origin="lower", extent=(0, world.size[0], 0, world.size[1]), cmap="Greens", alpha=0.25,
                  vmin=0, vmax=1.6, zorder=0)
        draw_world(ax, world)
        ax.set_title(f"{name}: {world.size[0]:g} m x {world.size[1]:g} m, {world.n_walls} wall segments",
                     fontsize=9)
        ax.set_xlim(-0.15, max(world.size[0], max((lamp.x for lamp in world.lamps), default=0)) + 0.15)
        ax.set_ylim(-0.15, world.size[1] + 0.15)
        ax.set_xlabel("x (m)")
        ax.grid(alpha=0.2)
    axes[0].set_ylabel("y (m)")
    fig.suptitle("Built-in worlds (green: where the robot's centre can go from the start; star: lamp)", fontsize=10)
    path = out / "worlds.png"
    fig.savefig(path)
    plt.close(fig)
    return path
