"""How often random k-bit corruptions of frames on the wire are accepted.

    python -m tools.bench.fuzz_wire [TRIALS] [SEED]

For k = 1, 2, 3: a random frame with k bits flipped, then an intact
sentinel frame; counts wrong frames delivered and sentinels lost.  Quoted
in protocol/SPEC.md, tested small in tests/test_protocol_robustness.py; not
a `twinbot bench` benchmark (those: docs/benchmarks.md).
"""
from __future__ import annotations

import random
import sys

from protocol import framing, messages

TYPES = [t for t, _n, _f in messages.LAYOUTS]


def trial(rng: random.Random, k: int, enc: framing.FrameEncoder, sentinel: bytes) -> tuple[bool, bool]:
    """(a wrong frame was accepted, the sentinel was lost) for one k-bit corruption."""
    t = rng.choice(TYPES)
    size = messages.PAYLOAD_SIZE[t] + (rng.randint(0, 30) if messages.VARIABLE[t] else 0)
    payload = bytes(rng.choice((0, 0, 1, 0xFF, rng.randrange(256))) for _ in range(size))
    seq = rng.randrange(256)
    enc.seq = seq
    frame = bytearray(enc.encode(t, payload))
    for bit in rng.sample(range(len(frame) * 8), k):
        frame[bit // 8] ^= 1 << (bit % 8)
    dec = framing.FrameDecoder()
    out = dec.decode_all(bytes(frame) + sentinel)
    lost = not out or out[-1] != (messages.PARAM_GET, 77, b"\x2a")
    wrong = any(o != (t, seq, payload) for o in (out if lost else out[:-1]))
    return wrong, lost


def measure(trials: int, seed: int = 1) -> dict[int, tuple[int, int]]:
    """k -> (wrong frames accepted, sentinels lost) over `trials` corruptions each."""
    rng = random.Random(seed)
    enc = framing.FrameEncoder()
    s = framing.FrameEncoder()
    s.seq = 77
    sentinel = s.encode(messages.PARAM_GET, b"\x2a")
    out = {}
    for k in (1, 2, 3):
        wrong = lost = 0
        for _ in range(trials):
            w, l_ = trial(rng, k, enc, sentinel)
            wrong += w
            lost += l_
        out[k] = (wrong, lost)
    return out


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    trials = int(args[0]) if args else 100000
    seed = int(args[1]) if len(args) > 1 else 1
    for k, (wrong, lost) in measure(trials, seed).items():
        print(f"{k}-bit corruptions: {wrong} of {trials} accepted as a wrong frame "
              f"({wrong / trials:.2e}), next frame lost {lost} times")
    return 0


if __name__ == "__main__":
    sys.exit(main())
