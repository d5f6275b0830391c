"""Regenerate tests/data/firmware_golden.jsonl, the firmware's golden vectors (docs/firmware-vectors.md).

    python -m tests.data.make_firmware_vectors [OUTPUT]

The file pins the exact integer outputs of the firmware's control path (fz fuzzy
controller, ir IR loop, od odometry, wh wheel PI), so that every port can be shown to
compute the same bits.  Deterministic: one seeded random.Random, integers only, no clock.
Regenerate only when a firmware output changes on purpose.
"""
from __future__ import annotations

import json
import random
import sys
from pathlib import Path

from firmware import fuzzy, ir, odometry, wheels

OUTPUT = Path(__file__).resolve().with_name("firmware_golden.jsonl")
SEED = 0x7B0F
FORMAT_VERSION = 1

N_FUZZY = 10000
N_IR = 1000
N_ODOMETRY = 1000
N_WHEEL = 500

DEFAULT_SPEED = 200  # every fuzzy vector is evaluated at this max_speed and at one other
SPECIAL_SPEEDS = (0, 1, 2, 3, 7, 99, 100, 101, 999, 1000)
ODOMETRY_EVERY = 10  # poses are recorded after every 10th step and after the last
ADC_MAX = ir.ADC_MAX
ODOMETRY_METHODS = (odometry.EULER, odometry.MIDPOINT, odometry.EXACT)
IR_METHODS = (ir.AVG_NONE, ir.AVG_MOVING, ir.AVG_EXPONENTIAL, ir.AVG_MEDIAN3)

LAYOUT = {
    "fz": "[\"fz\", readings[8], speed, out]: out = left, right with max_speed fuzzy_speed for rule set 0, "
          "then rule set 1, then the same with max_speed = speed (8 ints)",
    "ir": "[\"ir\", power_pct, method, window, inputs, expected]: inputs[c] = ambient[8] + on[8] "
          "(what the test HAL returns with the emitters off / on), expected[c] = reflected[8] + "
          "value[8] + [saturated 0/1], per acquire()",
    "od": "[\"od\", wheel_diameter_um, wheel_base_um, ticks_per_rev, start, steps, expected]: steps = "
          "dl0, dr0, dl1, dr1, ...; start null: step(dl, dr) per step; start [l, r]: update() with the "
          "cumulative counts from l, r (the first update() only sets the reference); expected = "
          "[um_per_tick_q8, heading_per_tick, poses(EULER), poses(MIDPOINT), poses(EXACT)], poses = "
          "x_um, y_um, heading after step i when (i + 1) % every == 0 or i is the last",
    "wh": "[\"wh\", um_per_tick_q8, kp, ki, limit_ma, steps]: step = [ticks, dt_ms, setpoint, speed, "
          "current, acc, clamped 0/1]: measure(ticks, dt_ms), then control(setpoint, dt_ms) or, "
          "setpoint null, reset(); then the loop's speed, current, acc, clamped",
}


class ReplayHal:
    """The IR test HAL: read_ir() gives the cycle's ambient readings while the
    emitters are off (set_emitters(0)), its 'on' readings while they are on."""

    def __init__(self) -> None:
        self.emitters = 0
        self.ambient = [0] * 8
        self.on = [0] * 8

    def set_emitters(self, pct: int) -> None:
        self.emitters = pct

    def read_ir(self, out: list[int]) -> None:
        src = self.on if self.emitters else self.ambient
        for i in range(8):
            out[i] = src[i]


def _clamp(v: int, lo: int = 0, hi: int = ADC_MAX) -> int:
    return lo if v < lo else hi if v > hi else v


# -- fuzzy -----------------------------------------------------------------

def _fuzzy_readings(rng: random.Random) -> list[list[int]]:
    lo, hi = fuzzy.NEAR_LO, fuzzy.NEAR_HI
    out: list[list[int]] = []
    for v in (0, 1, lo - 1, lo, lo + 1, 100, (lo + hi) // 2, hi - 1, hi, hi + 1, 2048, ADC_MAX - 1, ADC_MAX):
        out.append([v] * 8)
    single = [1, lo - 1, lo, lo + 1, lo + 2, 50, 100, 200, 300, 370, 400, 500, 600, 650,
              hi - 2, hi - 1, hi, hi + 1, 1000, 2000, ADC_MAX - 1, ADC_MAX]
    for s in range(8):  # one obstacle, clean background
        for v in single + [rng.randint(lo, hi) for _ in range(10)]:
            r = [0] * 8
            r[s] = v
            out.append(r)
    for s in range(8):  # one obstacle, noisy background
        for _ in range(20):
            r = [rng.randint(0, 60) for _ in range(8)]
            r[s] = rng.randint(lo, ADC_MAX)
            out.append(r)
    for s in range(8):  # two obstacles: neighbours, then opposite sensors
        for other in ((s + 1) % 8, (s + 4) % 8):
            for _ in range(15):
                r = [rng.randint(0, 30) for _ in range(8)]
                r[s] = rng.randint(0, ADC_MAX)
                r[other] = rng.randint(0, ADC_MAX)
                out.append(r)
    for _ in range(1500):  # every reading close to a ramp end, or inside the ramp
        out.append([rng.choice((lo + rng.randint(-5, 5), hi + rng.randint(-5, 5), rng.randint(lo, hi)))
                    for _ in range(8)])
    for _ in range(800):  # saturated sensors
        r = [rng.randint(0, ADC_MAX) for _ in range(8)]
        for s in range(8):
            if rng.randrange(3) == 0:
                r[s] = ADC_MAX
        out.append(r)
    for _ in range(2000):  # realistic: low background, 0..3 obstacles
        r = [rng.randint(0, 80) for _ in range(8)]
        for _ in range(rng.randint(0, 3)):
            r[rng.randrange(8)] = rng.randint(lo, ADC_MAX)
        out.append(r)
    while len(out) < N_FUZZY:  # anything
        out.append([rng.randint(0, ADC_MAX) for _ in range(8)])
    return out


def _fuzzy_cases(rng: random.Random) -> list[list]:
    ctl = [fuzzy.FuzzyController(0, DEFAULT_SPEED), fuzzy.FuzzyController(1, DEFAULT_SPEED)]
    cases = []
    for k, readings in enumerate(_fuzzy_readings(rng)):
        other = SPECIAL_SPEEDS[(k // 5) % len(SPECIAL_SPEEDS)] if k % 5 == 0 else rng.randint(0, 1000)
        res = []
        for speed in (DEFAULT_SPEED, other):
            for rs in (0, 1):
                c = ctl[rs]
                c.configure(rs, speed)
                c.infer(readings)
                res += [c.left, c.right]
        cases.append(["fz", readings, other, res])
    return cases


# -- IR loop ---------------------------------------------------------------

def _ir_inputs(rng: random.Random, power: int, n: int) -> list[list[int]]:
    """n cycles of ambient[8] + on[8] readings under a changing light."""
    scene = rng.randrange(6)
    amb = [rng.randint(0, 400) for _ in range(8)]
    if scene == 1:  # sunlight on some sensors: saturation
        for s in range(8):
            if rng.randrange(2):
                amb[s] = rng.randint(3000, ADC_MAX)
    refl = [rng.choice((0, 0, rng.randint(0, 200), rng.randint(0, 4000))) for _ in range(8)]
    cycles = []
    for c in range(n):
        if scene == 2:  # ramping light
            amb = [_clamp(a + rng.randint(-20, 120)) for a in amb]
        elif scene == 3:  # flicker: the light changes between the two reads
            pass
        elif scene == 4:  # light switched on / off
            if rng.randrange(4) == 0:
                level = rng.choice((0, rng.randint(500, 2500), ADC_MAX))
                amb = [_clamp(level + rng.randint(-50, 50)) for _ in range(8)]
        else:
            amb = [_clamp(a + rng.randint(-15, 15)) for a in amb]
        refl = [_clamp(r + rng.randint(-100, 100), 0, 4000) for r in refl]  # the robot moves
        ambient = list(amb)
        on = []
        for s in range(8):
            light = amb[s]
            if scene == 3 or rng.randrange(10) == 0:
                light = _clamp(light + rng.randint(-300, 300))  # may read below the ambient
            on.append(_clamp(light + refl[s] * power // 100 + rng.randint(-8, 8)))
        cycles.append(ambient + on)
    return cycles


def _ir_cases(rng: random.Random) -> list[list]:
    hal = ReplayHal()
    cases = []
    for k in range(N_IR):
        method = IR_METHODS[k % 4]
        window = 1 + (k // 4) % 16 if k < 128 else rng.randint(1, 16)
        power = rng.choice((0, 100, rng.randint(1, 100), rng.randint(1, 100)))
        arr = ir.IRArray(hal, power, method, window)
        inputs = _ir_inputs(rng, power, rng.randint(5, 20))
        expected = []
        for cyc in inputs:
            hal.ambient = cyc[:8]
            hal.on = cyc[8:]
            arr.acquire()
            expected.append(list(arr.reflected) + list(arr.value) + [1 if arr.saturated else 0])
        cases.append(["ir", power, method, window, inputs, expected])
    return cases


# -- odometry --------------------------------------------------------------

def _odometry_steps(rng: random.Random, n: int, base: int) -> list[int]:
    """n (dl, dr) steps, flat; base = ticks of a typical 40 mm step."""
    kind = rng.randrange(8)
    steps = []
    ratio = rng.randint(-100, 100)
    for _ in range(n):
        v = rng.randint(-base, base)
        if kind == 0:  # straight
            dl = dr = v
        elif kind == 1:  # rotation on the spot
            dl, dr = -v, v
        elif kind == 2:  # constant-curvature arc
            dl, dr = v, v * ratio // 100
        elif kind == 3:  # large turns (up to several turns in one step: sinc out of range)
            w = rng.randint(0, 40 * base)
            dl, dr = (v - w, v + w) if rng.randrange(2) else (v + w, v - w)
        elif kind == 4:  # one wheel only
            dl, dr = (v, 0) if rng.randrange(2) else (0, v)
        elif kind == 5:  # stop and go
            dl, dr = (0, 0) if rng.randrange(3) == 0 else (v, v + rng.randint(-base // 8, base // 8))
        elif kind == 6:  # small noisy steps
            dl, dr = rng.randint(-3, 3), rng.randint(-3, 3)
        else:  # anything
            dl, dr = v, rng.randint(-base, base)
        steps += [dl, dr]
    return steps


def _wrap(count: int) -> int:
    """An encoder count as the HALs keep it: wrapped within [-2**29, 2**29)."""
    return (count + 2 ** 29) % 2 ** 30 - 2 ** 29


def _odometry_run(d: int, w: int, tpr: int, method: int, start: list[int] | None,
                  steps: list[int]) -> tuple[int, int, list[int]]:
    od = odometry.Odometry(d, w, tpr, method)
    n = len(steps) // 2
    poses: list[int] = []
    if start is not None:
        el, er = start
        od.update(el, er)
    for i in range(n):
        dl, dr = steps[2 * i], steps[2 * i + 1]
        if start is None:
            od.step(dl, dr)
        else:
            el = _wrap(el + dl)
            er = _wrap(er + dr)
            od.update(el, er)
        if (i + 1) % ODOMETRY_EVERY == 0 or i == n - 1:
            poses += [od.x_um, od.y_um, od.heading]
    return od.um_per_tick_q8, od.heading_per_tick, poses


def _odometry_cases(rng: random.Random) -> list[list]:
    cases = []
    for _ in range(N_ODOMETRY):
        d = rng.randint(20000, 80000)
        w = rng.randint(50000, 200000)
        tpr = rng.randint(100, 5000)
        base = max(1, 40000 * tpr * 113 // (355 * d))  # ticks per 40 mm
        steps = _odometry_steps(rng, rng.randint(10, 50), base)
        start = None
        if rng.randrange(3) == 0:
            start = [rng.choice((0, rng.randint(-10 ** 6, 10 ** 6), rng.randint(-2 ** 29, 2 ** 29 - 1),
                                 2 ** 29 - rng.randint(1, 500))) for _ in range(2)]
        q8 = hpt = 0
        expected: list = []
        for method in ODOMETRY_METHODS:
            q8, hpt, poses = _odometry_run(d, w, tpr, method, start, steps)
            expected.append(poses)
        cases.append(["od", d, w, tpr, start, steps, [q8, hpt] + expected])
    return cases


# -- wheel PI --------------------------------------------------------------

def _wheel_cases(rng: random.Random) -> list[list]:
    cases = []
    for _ in range(N_WHEEL):
        d = rng.randint(20000, 80000)
        tpr = rng.randint(100, 5000)
        q8 = odometry.Odometry(d, 96000, tpr).um_per_tick_q8
        kp = rng.choice((0, 2000, 100000, rng.randint(0, 100000), rng.randint(0, 10000)))
        ki = rng.choice((0, 20000, 100000, rng.randint(0, 100000), rng.randint(0, 50000)))
        limit = rng.choice((0, 500, 3000) + tuple(rng.randint(1, 3000) for _ in range(7)))
        loop = wheels.WheelLoop(q8, kp, ki, limit)
        ticks = rng.choice((0, rng.randint(-2 ** 29, 2 ** 29 - 1), 2 ** 29 - rng.randint(1, 2000)))
        speed = rng.randint(-300, 300)  # mm/s, the wheel's true speed
        setpoint = rng.randint(-1000, 1000)
        steps = []
        for i in range(rng.randint(10, 30)):
            dt = 0 if i == 0 else rng.choice((40, 40, 40, rng.randint(10, 100), rng.randint(0, 1000)))
            if rng.randrange(8) == 0:
                setpoint = rng.choice((0, rng.randint(-1000, 1000), rng.randint(-50, 50)))
            speed += (setpoint - speed) // 3 + rng.randint(-20, 20)
            ticks = _wrap(ticks + (speed * dt * 256 + rng.randint(0, q8)) // q8)  # um over um per tick (Q8)
            sp = None if rng.randrange(15) == 0 else setpoint
            loop.measure(ticks, dt)
            if sp is None:
                loop.reset()
            else:
                loop.control(sp, dt)
            steps.append([ticks, dt, sp, loop.speed, loop.current, loop.acc, 1 if loop.clamped else 0])
        cases.append(["wh", q8, kp, ki, limit, steps])
    return cases


# -- the document ----------------------------------------------------------

def build() -> tuple[dict, list[list]]:
    """(header, cases), deterministically."""
    rng = random.Random(SEED)
    cases = _fuzzy_cases(rng) + _ir_cases(rng) + _odometry_cases(rng) + _wheel_cases(rng)
    counts = {k: 0 for k in LAYOUT}
    for c in cases:
        counts[c[0]] += 1
    header = {
        "format": FORMAT_VERSION, "generator": "tests/data/make_firmware_vectors.py", "seed": SEED,
        "counts": counts, "total": len(cases), "fuzzy_speed": DEFAULT_SPEED,
        "odometry_every": ODOMETRY_EVERY, "layout": LAYOUT,
    }
    return header, cases


def render(header: dict, cases: list[list]) -> str:
    """The header line, then one compact JSON case per line."""
    lines = [json.dumps(header, ensure_ascii=True, separators=(",", ":"))]
    lines += [json.dumps(c, separators=(",", ":")) for c in cases]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    out = Path(args[0]) if args else OUTPUT
    header, cases = build()
    out.parent.mkdir(parents=True, exist_ok=True)
    text = render(header, cases)
    out.write_text(text, encoding="ascii")
    print("wrote {} cases ({}) to {}, {} bytes".format(
        header["total"], ", ".join("{} {}".format(k, v) for k, v in header["counts"].items()), out, len(text)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
