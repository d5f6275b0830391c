"""Does this MicroPython allocate for an int past 2**30?  micropython tests/mp/bigint_probe.py

Prints the largest small int (sys.maxsize stands for the word size) and,
for x = 2**29 - 1 + 2**29 (the largest 31-bit small int) and x + 1, whether
computing it inside micropython.heap_lock() raised MemoryError.
"""
import sys

import micropython


def locked_sum(a, b, out):
    micropython.heap_lock()
    try:
        out[0] = a + b
        out[1] = 0
    except MemoryError:
        out[1] = 1
    micropython.heap_unlock()


def main():
    half = (1 << 29) - 1
    out = [0, 0]
    locked_sum(half, 1 << 29, out)  # 2**30 - 1
    small = out[1]
    locked_sum(1 << 29, 1 << 29, out)  # 2**30
    big = out[1]
    print("maxsize", sys.maxsize, "alloc at 2**30-1:", small, "alloc at 2**30:", big)


main()
