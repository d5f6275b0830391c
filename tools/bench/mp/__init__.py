"""Benchmark scripts that run under MicroPython itself (kept apart so no CPython bench module shadows protocol/ or firmware/ on their path)."""
