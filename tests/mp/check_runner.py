"""Runs a check script's check_* functions, on MicroPython and CPython alike.

tests/mp/counters_check.py and tests/mp/firmware_behaviour.py end with `run(LABEL, globals())`: it
prints 'LABEL: N checks ok', or 'LABEL: FAIL name error' for each check that fails and exits 1.
A MicroPython run needs this folder on its path (micropython_runner's `path=`).
"""
import sys


def checks(namespace):
    """The names of the check_* functions in a script's globals(), sorted."""
    return [name for name in sorted(namespace) if name.startswith("check_")]


def run(label, namespace):
    names = checks(namespace)
    failed = 0
    for name in names:
        try:
            namespace[name]()
        except Exception as exc:  # noqa: BLE001 - each check's failure is reported, the others still run
            failed += 1
            print(label + ": FAIL", name, repr(exc))
    if failed:
        sys.exit(1)
    print(label + ":", len(names), "checks ok")
