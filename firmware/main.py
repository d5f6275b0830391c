"""Start the firmware on whatever board this is (docs/firmware.md).

A board's /main.py holds two lines, written by `twinbot flash`:
`import firmware.main` and `firmware.main.start()`.  On an RP2040 the HAL is the real
hardware; under the unix port (the virtual board) it is the simulator's hardware link
named by TWINBOT_HW=host:port.  start() returns when mpremote (or a person) breaks into
the REPL.
"""
import sys

from firmware.robot import BreakToRepl, Robot


def make_hal() -> object:
    if sys.platform == "rp2":
        from firmware.hal_rp2040 import Rp2040Hal

        return Rp2040Hal()
    import os

    address = os.getenv("TWINBOT_HW")
    if not address or ":" not in address:
        raise RuntimeError("virtual board: set TWINBOT_HW=host:port of the simulator (twinbot board does)")
    host, port = address.rsplit(":", 1)
    from firmware.hal_sim_link import SimLinkHal

    return SimLinkHal(host, int(port))


def start() -> None:
    hal = make_hal()
    robot = Robot(hal)
    link = hal.link  # type: ignore[attr-defined]
    link.open()
    try:
        # A peer that restarted sends HELLO first (protocol/SPEC.md), so the host restarts its sequence
        # count instead of counting a gap: tests/test_virtual_board.py::test_a_soft_reset_starts_with_hello.
        robot.send_hello()
        robot.run()
    except BreakToRepl:
        pass
    finally:
        link.close()
        hal.set_currents(0, 0)  # type: ignore[attr-defined]
        hal.close()  # type: ignore[attr-defined]
