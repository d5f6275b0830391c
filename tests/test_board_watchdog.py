"""The virtual board's hardware watchdog, modelled on the simulator's side of its hardware link.

An RP2040's watchdog resets a stalled firmware, which stops the motor PWM.  The
simulator models it: HW_ACTUATE overdue by watchdog_s -> zero currents.
"""
from __future__ import annotations

import socket

from host_sim.controller.hardware_io import Sense
from host_sim.board.pil import PilLink
from protocol import messages as M
from protocol.framing import FrameEncoder


def _sense(tick: int) -> Sense:
    return Sense(tick_ms=tick, adc_off=[0] * 8, adc_on=[0] * 8, enc_l=0, enc_r=0, vbat_mv=7400)


def test_stalled_board_gets_zero_currents() -> None:
    link = PilLink(watchdog_s=0.2)
    board = socket.create_connection(("127.0.0.1", link.port))
    try:
        link.accept(timeout=2)
        enc = FrameEncoder()
        board.sendall(enc.encode(M.HW_ACTUATE, M.pack_payload(
            M.HW_ACTUATE, {"tick_ms": 0, "i_ref_l_ma": 300, "i_ref_r_ma": -300, "emitter_pct": 60})))
        a = link.exchange(_sense(0))
        assert (a.i_left_ma, a.i_right_ma) == (300, -300)
        a = link.exchange(_sense(40))  # the board's loop has stalled: no answer
        assert (a.i_left_ma, a.i_right_ma) == (0, 0) and link.watchdog_trips == 1
    finally:
        board.close()
        link.close()
