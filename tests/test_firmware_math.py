"""The firmware's integer trigonometry table is what its comment says it is."""
from __future__ import annotations

import math

from firmware import trig


def test_sin_table_is_the_rounded_quarter_wave() -> None:
    """SIN_TABLE[i] = round(16384 sin(pi/2 i/256)) for i = 0..256, and nothing more."""
    want = [round(16384 * math.sin(math.pi / 2 * i / 256)) for i in range(257)]
    assert list(trig.SIN_TABLE) == want
