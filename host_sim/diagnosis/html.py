"""The diagnosis as a self-contained HTML page (`twinbot diagnose --html`): the verdict, the effects, and
the pictures that show them, embedded as PNG: each located channel's residual against time and by regime,
before and after the fit, and the trajectory with the twin's prediction.  docs/diagnosis.md, "Output".
"""
from __future__ import annotations

import base64
import html
import io
from typing import Any

import numpy as np

from host_sim.diagnosis.channels import ACCUMULATED, judged_windows
from host_sim.diagnosis.compare import Comparison
from host_sim.diagnosis.locate import lag_blocks
from host_sim.diagnosis.phrasing import checked
from host_sim.diagnosis.report import Diagnosis
from host_sim.recordings.recording import Recording


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def residual_figure(rec: Recording, before: Comparison, after: Comparison | None, channel: str) -> str:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 2.6))
    t = rec.t[before.windows.index[:, 1:]]
    keep = judged_windows(channel, before.contact)
    ax.plot(t[keep].ravel(), before.channel(channel).residual()[keep].ravel(), ".", ms=2, color="tab:red",
            label="before: recorded − twin")
    if after is not None:
        ax.plot(t[keep].ravel(), after.channel(channel).residual()[keep].ravel(), ".", ms=2, color="tab:blue",
                label="after the fit")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(f"{channel} ({before.channel(channel).unit})")
    ax.legend(loc="upper right", fontsize=8, markerscale=4)
    return _png(fig)


def scale_figure(before: Comparison, after: Comparison | None, name: str) -> str:
    """A proportional error over whole windows: each window's residual total against its recorded total."""
    channel = next(c for c, acc in ACCUMULATED.items() if acc == name)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.2))
    for cmp, colour, label in ((before, "tab:red", "before: recorded − twin"), (after, "tab:blue", "after the fit")):
        if cmp is None:
            continue
        keep = ~cmp.contact
        ch = cmp.channel(channel)
        y = ch.y[keep].sum(axis=1)
        ax.plot(y, y - ch.y_hat[keep, 0].sum(axis=1), "o", ms=3, color=colour, label=label)
    ax.axhline(0, color="k", lw=0.5)
    unit = before.channel(channel).unit.replace("/period", "")
    ax.set_xlabel(f"{name} in a window, recorded ({unit})")
    ax.set_ylabel(f"recorded − twin ({unit})")
    ax.legend(fontsize=8)
    return _png(fig)


def regime_figure(finding_bins: list[dict[str, Any]], channel: str, unit: str, scatter: bool = False) -> str:
    """The mean residual in each regime where it is not noise; for a wheel that scatters without a bias,
    the RMS residual in each regime, largest first."""
    plt = _pyplot()
    bins = [b for b in finding_bins if b["key"] != "all"][:12]
    fig, ax = plt.subplots(figsize=(9, 0.35 * len(bins) + 1))
    ax.barh([str(b["regime"]) for b in bins], [float(b["rms" if scatter else "mean"]) for b in bins], color="tab:red")
    ax.axvline(0, color="k", lw=0.5)
    if scatter:  # each bin's z is its RMS in noise levels
        ax.axvline(float(bins[0]["rms"]) / float(bins[0]["z"]), color="k", ls="--", lw=1, label="noise level")
        ax.legend(fontsize=8)
    ax.set_xlabel(f"RMS residual of {channel} ({unit}) in each regime" if scatter else
                  f"mean residual of {channel} ({unit}) in the regimes where it is not noise")
    ax.invert_yaxis()
    return _png(fig)


def lag_figure(before: Comparison, after: Comparison | None, channel: str, lag_s: float, period: float) -> str:
    """A wheel that runs behind the twin: each block's residual count against the twin's change of speed
    across it, before and after the fit, with the slope of the lag located."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.2))
    change, sums = lag_blocks(before.channel(channel), ~before.contact)
    ax.plot(change.ravel(), sums.ravel(), "o", ms=2, color="tab:red", label="before: recorded − twin")
    if after is not None:
        after_change, after_sums = lag_blocks(after.channel(channel), ~after.contact)
        ax.plot(after_change.ravel(), after_sums.ravel(), "o", ms=2, color="tab:blue", label="after the fit")
    x = np.array([float(change.min()), float(change.max())]) if change.size else np.zeros(2)
    ax.plot(x, -lag_s / period * x, "k--", lw=1, label=f"{1000 * lag_s:.0f} ms behind")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("the twin's change of speed across a 0.2 s block (ticks/period)")
    ax.set_ylabel("recorded − twin, summed (ticks)")
    ax.legend(fontsize=8)
    return _png(fig)


def trajectory_figure(rec: Recording, before: Comparison, after: Comparison | None) -> str | None:
    if rec.pose is None or before.pose is None:
        return None
    plt = _pyplot()
    panels = [("before", before)] + ([("after", after)] if after is not None and after.pose is not None else [])
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.5), squeeze=False)
    for ax, (title, cmp) in zip(axes[0], panels):
        ax.plot(rec.pose[:, 0], rec.pose[:, 1], color="k", lw=1, label="recorded (tracker)")
        assert cmp.pose is not None
        for w in range(len(cmp.pose)):
            ax.plot(cmp.pose[w, :, 0], cmp.pose[w, :, 1], color="tab:red" if title == "before" else "tab:blue",
                    lw=0.8, label="twin, from each window's start" if w == 0 else None)
        ax.set_title(f"{title} the fit")
        ax.set_aspect("equal")
        ax.legend(fontsize=8)
    return _png(fig)


def render(rec: Recording, d: Diagnosis) -> str:
    """The whole page."""
    before = d.comparisons[0]
    parts = [f"<h1>twinbot diagnose: {html.escape(d.recording)}</h1>",
             f"<p><b>Verdict: {html.escape(d.verdict)}</b></p>"]
    parts += [f"<p><i>{html.escape(checked(item))}</i></p>" for item in d.recording_checks]
    parts += [f"<p><i>{html.escape(n)}</i></p>" for n in d.notes]
    parts.append("<pre>" + html.escape(d.summary()) + "</pre>")
    traj = trajectory_figure(rec, d.comparisons[-1], d.after_long)
    if traj:
        parts.append(f'<h2>Trajectory</h2><img src="{traj}">')
    for item in d.located:
        ch = item["channel"]
        finding = next((f for f in before.findings if f.channel == ch), None)
        parts.append(f"<h2>{html.escape(ch)}</h2><p>{html.escape(item['words'])}</p>")
        if finding is None:  # found apart from the twin's residuals (a clip, odometry): its words alone
            continue
        if ch in ACCUMULATED.values():
            parts.append(f'<img src="{scale_figure(before, d.after, ch)}">')
            continue
        parts.append(f'<img src="{residual_figure(rec, before, d.after, ch)}">')
        if finding.lag is not None:
            parts.append(f'<img src="{lag_figure(before, d.after, ch, finding.lag, rec.sample_period)}">')
        elif len(finding.bins) > 1:
            figure = regime_figure(finding.bins, ch, before.channel(ch).unit, scatter=finding.rms is not None)
            parts.append(f'<img src="{figure}">')
    rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{d.fit_before[k]:.1f}</td>"
                   f"<td>{d.fit_after.get(k, float('nan')):.1f}</td>"
                   f"<td>{(f'{d.fit_ceiling[k]:.1f}' if k in d.fit_ceiling else '')}</td></tr>" for k in d.fit_before
                   if np.isfinite(d.fit_before[k]))
    parts.append(f"<h2>Held-out fit %</h2><table border=1 cellpadding=3><tr><th>channel</th><th>before</th>"
                 f"<th>after</th><th>ceiling (a twin right but for the encoders' rounding)</th></tr>{rows}</table>")
    return ("<!doctype html><html><head><meta charset='utf-8'><title>twinbot diagnose</title></head>"
            "<body style='font-family: sans-serif; max-width: 1000px'>" + "\n".join(parts) + "</body></html>\n")
