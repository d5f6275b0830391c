"""The few things CPython and MicroPython spell differently (docs/protocol.md).

`const` is MicroPython's compile-time constant (its compiler folds any
`X = const(1)` at module level); on CPython it is the identity.
`IS_MICROPYTHON` picks allocation-free code paths where CPython would prefer
a C-speed built-in; both paths give identical results (the tests run both).
"""
import sys

try:
    from micropython import const
except ImportError:  # CPython

    def const(value):  # type: ignore[no-untyped-def,no-redef,misc]
        return value


IS_MICROPYTHON = sys.implementation.name == "micropython"

__all__ = ["const", "IS_MICROPYTHON"]
