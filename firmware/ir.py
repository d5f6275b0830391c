"""IR acquisition with ambient-light subtraction (paper, section 3.3; docs/firmware.md).

Every cycle: emitters off -> read the ambient level of the 8 sensors -> emitters on at
power L -> read -> reflected = on - ambient (clamped at 0), then the selected averaging.
On the paper's robot this takes well under the 40 ms cycle, so both readings see the
same ambient light.
"""
from array import array

from protocol.compat import const

N_SENSORS = const(8)
ADC_MAX = const(4095)  # 12-bit ADC counts; a reading there is saturated
MAX_WINDOW = const(16)

AVG_NONE = const(0)
AVG_MOVING = const(1)  # moving average of `window` samples
AVG_EXPONENTIAL = const(2)  # y += (x - y) / 2**window
AVG_MEDIAN3 = const(3)  # median of the last 3 samples

_EXP_BITS = const(6)  # fractional bits kept by the exponential filter


class IRArray:
    """The eight emitter/phototransistor pairs; acquire() allocates nothing."""

    def __init__(self, hal: object, power_pct: int = 60, method: int = AVG_NONE, window: int = 4) -> None:
        self.hal = hal
        self.ambient = [0] * N_SENSORS  # ADC counts, emitters off
        self.on = [0] * N_SENSORS  # ADC counts, emitters on
        self.reflected = [0] * N_SENSORS  # on - ambient, clamped at 0
        self.value = [0] * N_SENSORS  # after averaging: what the controller sees
        self.saturated = False
        self.power = power_pct
        self.method = method
        self.window = window
        self._hist = array("i", [0] * (N_SENSORS * MAX_WINDOW))  # compact: RAM matters
        self._sum = [0] * N_SENSORS
        self._exp = [0] * N_SENSORS
        self._pos = 0
        self._count = 0
        self.configure(power_pct, method, window)

    def configure(self, power_pct: int, method: int, window: int) -> None:
        """Change L or the averaging; the averaging restarts from empty."""
        if not 0 <= power_pct <= 100:
            raise ValueError("emitter power must be 0..100 %")
        if not AVG_NONE <= method <= AVG_MEDIAN3:
            raise ValueError("averaging method must be 0..3")
        if not 1 <= window <= MAX_WINDOW:
            raise ValueError("window must be 1..16")
        self.power = power_pct
        self.method = method
        self.window = window
        self._pos = 0
        self._count = 0
        for i in range(N_SENSORS):
            self._sum[i] = 0
        for k in range(N_SENSORS * MAX_WINDOW):
            self._hist[k] = 0

    def acquire(self) -> None:
        hal = self.hal
        hal.set_emitters(0)  # type: ignore[attr-defined]
        hal.read_ir(self.ambient)  # type: ignore[attr-defined]
        hal.set_emitters(self.power)  # type: ignore[attr-defined]
        hal.read_ir(self.on)  # type: ignore[attr-defined]
        hal.set_emitters(0)  # type: ignore[attr-defined]
        self.subtract()
        self.average()

    def subtract(self) -> None:
        sat = False
        amb = self.ambient
        on = self.on
        out = self.reflected
        for i in range(N_SENSORS):
            v = on[i]
            if v >= ADC_MAX:
                sat = True
            r = v - amb[i]
            out[i] = r if r > 0 else 0
        self.saturated = sat

    def average(self) -> None:
        x = self.reflected
        y = self.value
        method = self.method
        if method == AVG_NONE:
            for i in range(N_SENSORS):
                y[i] = x[i]
            return
        if self._count < 0x3FFFFFFF:  # saturates inside the RP2040's small ints
            self._count += 1
        if method == AVG_EXPONENTIAL:
            k = self.window
            s = self._exp
            first = self._count == 1
            for i in range(N_SENSORS):
                target = x[i] << _EXP_BITS
                s[i] = target if first else s[i] + ((target - s[i]) >> k)
                y[i] = (s[i] + (1 << (_EXP_BITS - 1))) >> _EXP_BITS
            return
        hist = self._hist
        pos = self._pos
        if method == AVG_MOVING:
            n = self.window
            total = self._sum
            filled = self._count if self._count < n else n
            for i in range(N_SENSORS):
                slot = i * MAX_WINDOW + pos
                total[i] += x[i] - hist[slot]
                hist[slot] = x[i]
                y[i] = (2 * total[i] + filled) // (2 * filled)
            self._pos = pos + 1 if pos + 1 < n else 0
            return
        # Median of the last 3 samples; until there are 3, the newest sample.
        for i in range(N_SENSORS):
            base = i * MAX_WINDOW
            hist[base + pos] = x[i]
            if self._count < 3:
                y[i] = x[i]
                continue
            a = hist[base]
            b = hist[base + 1]
            c = hist[base + 2]
            lo = a if a < b else b
            hi = b if a < b else a
            y[i] = lo if c < lo else hi if c > hi else c
        self._pos = pos + 1 if pos < 2 else 0
