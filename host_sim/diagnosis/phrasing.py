"""Findings in words a robotics engineer reads at a glance (docs/diagnosis.md, "Output")."""
from __future__ import annotations

from typing import Any

from host_sim.diagnosis.channels import SENSOR_NAMES
from host_sim.diagnosis.locate import Finding
from host_sim.diagnosis.verdict import Judgement


def what(channel: str, mean: float) -> str:
    """What the robot does differently from the twin, from the sign of recorded minus twin."""
    more = mean > 0
    if channel in ("wheel_l", "wheel_r"):
        side = "left" if channel == "wheel_l" else "right"
        return f"the {side} wheel turns {'faster' if more else 'slower'} than the twin's"
    if channel == "forward":
        return f"the robot advances {'more' if more else 'less'} per period than the twin"
    if channel == "travel":
        return f"the robot travels {100 * abs(mean):.1f} % {'farther' if more else 'less far'} than the twin"
    if channel == "turn":
        return f"the robot turns {100 * abs(mean):.1f} % {'more' if more else 'less'} than the twin"
    if channel in ("count_l", "count_r"):
        side = "left" if channel == "count_l" else "right"
        return f"the {side} encoder counts {100 * abs(mean):.1f} % {'more' if more else 'less'} than the twin's"
    if channel == "lateral":
        return f"the robot drifts to its {'left' if more else 'right'} where the twin does not"
    if channel == "heading_rate":
        return f"the robot turns {'more to the left' if more else 'more to the right'} than the twin"
    if channel.startswith("ir_"):
        return f"sensor {SENSOR_NAMES[int(channel[3:])]} sees {'more' if more else 'less'} reflected light than the twin's"
    if channel.startswith("amb_"):
        return f"sensor {SENSOR_NAMES[int(channel[4:])]} sees {'more' if more else 'less'} ambient light than the twin's"
    if channel == "vbat":
        return f"the battery voltage is {'higher' if more else 'lower'} than the twin's"
    return f"{channel} differs"


def spans_text(spans: list[tuple[float, float]], most: int = 4) -> str:
    if not spans:
        return ""
    longest = sorted(sorted(spans, key=lambda s: s[0] - s[1])[:most])
    text = ", ".join(f"{a:.0f}–{b:.0f} s" if round(b) > round(a) else f"{a:.1f}–{b:.1f} s" for a, b in longest)
    return text + (f" and {len(spans) - most} more" if len(spans) > most else "")


def sentence(f: Finding) -> str:
    """e.g. "the left wheel turns slower than the twin's at low left-wheel speed, 12–14 s, 40–52 s"."""
    side = "left" if f.channel == "wheel_l" else "right"
    if f.rms is not None:  # no bias: "the left wheel's speed scatters about the twin's (RMS 17 times its noise) ..."
        parts = [f"the {side} wheel's speed scatters about the twin's (RMS {f.rms / f.noise:.0f} times its noise)"]
    elif f.lag is not None and f.channel.startswith("ir_"):  # "sensor S5 back's reading runs 21 ms behind the ..."
        parts = [f"sensor {SENSOR_NAMES[int(f.channel[3:])]}'s reading runs {1000 * abs(f.lag):.0f} ms "
                 f"{'behind' if f.lag > 0 else 'ahead of'} the tracked pose's"]
    elif f.lag is not None:  # "the left wheel runs 31 ms behind the twin's whenever its speed changes"
        parts = [f"the {side} wheel runs {1000 * abs(f.lag):.0f} ms {'behind' if f.lag > 0 else 'ahead of'} the twin's"]
    else:
        parts = [what(f.channel, f.mean)]
    parts.append(f.regime if f.regime else "everywhere")
    text = " ".join(parts)
    when = spans_text(f.spans)
    return f"{text}, {when}" if when else text


CHANNEL_WORDS = {"wheel_l": "the left wheel", "wheel_r": "the right wheel", "count_l": "the left encoder's window totals",
                 "count_r": "the right encoder's window totals", "forward": "the robot's advance", "lateral":
                 "the robot's sideways drift", "heading_rate": "the robot's turn rate", "travel": "each window's travel",
                 "turn": "each window's turn", "vbat": "the battery voltage"}


def channel_words(channel: str) -> str:
    """e.g. "the left wheel", "sensor S3 left's reflected light"."""
    if channel.startswith(("ir_", "amb_")):
        kind = "reflected" if channel.startswith("ir_") else "ambient"
        return f"sensor {SENSOR_NAMES[int(channel.split('_')[1])]}'s {kind} light"
    return CHANNEL_WORDS.get(channel, channel)


def test_block_words(j: Judgement, block: dict[str, Any]) -> str:
    """What a twin leaves in a channel on the test block, e.g. "on the test block (68-90 s) the left wheel is
    left 2.3 times its noise (RMS), drifting in time (trend t = 5.1)"."""
    what = []
    if not j.near:
        what.append(f"is left {j.rms_noise:.1f} times its noise (RMS)")
    if not j.steady:
        what.append(f"drifts in time (trend t = {j.trend_t:.1f})")
    if not j.white:
        what.append(f"is not white (Ljung-Box p = {j.white_p:.2g})")
    return f"on the test block ({block['from_s']:.0f}-{block['to_s']:.0f} s) {channel_words(j.channel)} " + ", ".join(what)


def drift_words(j: Judgement, change: float, span: list[float]) -> str:
    """A channel whose held-out windows drift, e.g. "a drift over the recording in the left wheel: its windows'
    mean residual moves by -2.4 noise levels from 1 s to 89 s (trend t = -5.3), which no constant twin follows"."""
    return (f"a drift over the recording in {channel_words(j.channel)}: its windows' mean residual moves by "
            f"{change:+.1f} noise levels from {span[0]:.0f} s to {span[1]:.0f} s (trend t = {j.trend_t:.1f}), which "
            f"no constant twin follows")


def checked(item: dict[str, Any]) -> str:
    """A note of loading's checks (host_sim/recordings/checks.py, Note.to_json) as the report says it: the
    recording's timing or counts as mended, which the diagnosis never fits as physics."""
    return f"{'the test recording' if item.get('test') else 'recording'} ({item['name']}): {item['text']}"
