"""Processor in the loop: the firmware on a virtual board under MicroPython (docs/firmware.md).

This process is the board's hardware and its host: readings and outputs travel as
HW_SENSE / HW_ACTUATE frames over the board's hardware link (TCP on 127.0.0.1), commands
over its serial port.  SIL (host_sim/controller/sil.py) and PIL feed the firmware the same
bytes in the same cycles, so in fixed-step mode they give the same trajectory bit for bit.
"""
from __future__ import annotations

import socket
import tempfile
import time
from pathlib import Path

from host_sim.controller.hardware_io import TICK_MASK, Actuate, Sense, setup_frames
from host_sim.physics.params import RobotParams
from protocol import messages as M
from protocol.framing import HEADER_SIZE, FrameDecoder, FrameEncoder


class PilLink:
    """The simulator's end of a virtual board's hardware link (TCP on 127.0.0.1)."""

    def __init__(self, watchdog_s: float | None = None) -> None:
        # watchdog_s: the board's hardware watchdog, modelled here.  If no
        # HW_ACTUATE comes that long after a HW_SENSE (the firmware's loop
        # stalled), the motors get zero current, as an RP2040's watchdog
        # reset would leave them; None: wait (lockstep runs, up to 10 s).
        self.watchdog_s = watchdog_s
        self.watchdog_trips = 0
        self.last_emitter = 0
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.conn: socket.socket | None = None
        self.enc = FrameEncoder()
        self.dec = FrameDecoder()

    def accept(self, timeout: float) -> None:
        self.server.settimeout(timeout)
        try:
            self.conn, _ = self.server.accept()
        except socket.timeout:
            raise RuntimeError(f"the virtual board did not connect its hardware link within {timeout} s") from None
        self.conn.settimeout(10)
        self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def exchange(self, s: Sense) -> Actuate:
        """Send one HW_SENSE, wait for the board's HW_ACTUATE (one answers each, in lockstep)."""
        assert self.conn is not None
        payload = M.pack_payload(M.HW_SENSE, {"tick_ms": s.tick_ms & TICK_MASK, "adc_off": s.adc_off,
                                              "adc_on": s.adc_on, "enc_l": s.enc_l, "enc_r": s.enc_r,
                                              "vbat_mv": s.vbat_mv})
        self.conn.sendall(self.enc.encode(M.HW_SENSE, payload))
        dec = self.dec
        self.conn.settimeout(10 if self.watchdog_s is None else self.watchdog_s)
        while True:
            try:
                data = self.conn.recv(4096)
            except socket.timeout:
                if self.watchdog_s is not None:
                    self.watchdog_trips += 1
                    return Actuate(0, 0, self.last_emitter)
                raise RuntimeError("the virtual board did not answer HW_SENSE within 10 s") from None
            if not data:
                raise RuntimeError("the virtual board closed its hardware link (it stopped or was reset)")
            i, end = 0, len(data)
            while i < end:
                i = dec.feed(data, i, end)
                if dec.ready and dec.msg_type == M.HW_ACTUATE:
                    f = M.unpack_payload(M.HW_ACTUATE, dec.body[HEADER_SIZE:HEADER_SIZE + dec.payload_len])
                    self.last_emitter = f["emitter_pct"]  # type: ignore[assignment]
                    return Actuate(f["i_ref_l_ma"], f["i_ref_r_ma"], f["emitter_pct"])  # type: ignore[arg-type]

    def close(self) -> None:
        if self.conn:
            self.conn.close()
        self.server.close()


class PilController:
    """The firmware on a virtual board; this process is its hardware and its host."""

    name = "PIL"

    def __init__(self, rule_set: int = 1, flash_dir: Path | None = None, log: Path | None = None,
                 params: RobotParams | None = None) -> None:
        from host_sim.board.virtual_board import VirtualBoard, factory_image
        from host_sim.board.serial_link import SerialLink

        self._tmp = None
        if flash_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="twinbot-pil-")
            flash_dir = Path(self._tmp.name)
            factory_image(flash_dir)
        self.link = PilLink()
        self.board = VirtualBoard(str(flash_dir), self.link.port, log)
        try:
            self.link.accept(timeout=20)
            self.host = SerialLink.open(self.board.path)
            for frame in setup_frames(rule_set, params=params):
                self.host.send_raw(frame)
            time.sleep(0.2)  # the commands wait in the board's input before cycle 0
        except Exception:
            self.close()
            raise

    def send(self, frame: bytes) -> None:
        """A frame from the host, over the board's serial port."""
        self.host.send_raw(frame)

    def cycle(self, s: Sense) -> Actuate:
        return self.link.exchange(s)

    def telemetry(self, wait: float = 0.0) -> list[dict[str, object]]:
        """TELEMETRY received on the board's serial port since the last call, waiting up to `wait` s for more."""
        frames: list[dict[str, object]] = []
        while True:
            got = self.host.poll(wait)
            if not got:
                return frames
            frames += [f.fields for f in got if f.msg_type == M.TELEMETRY]

    def close(self) -> None:
        for closer in (getattr(self, "host", None), getattr(self, "link", None), getattr(self, "board", None)):
            if closer is not None:
                try:
                    closer.close()
                except Exception:  # noqa: BLE001 - closing down
                    pass
        if self._tmp:
            self._tmp.cleanup()
