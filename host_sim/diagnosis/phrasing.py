"""Findings in words a robotics engineer reads at a glance (docs/diagnosis.md, "Output")."""
from __future__ import annotations

from host_sim.diagnosis.channels import SENSOR_NAMES
from host_sim.diagnosis.locate import Finding


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
