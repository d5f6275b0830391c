"""What drives a simulated robot, one control cycle at a time.

Every controller takes the hardware's readings for a cycle (a `Sense`: what
a HW_SENSE frame carries) and returns its outputs (an `Actuate`: what a
HW_ACTUATE frame carries):

- SilController: the firmware's own modules, in this process (software in
  the loop), on firmware.hal_sensed.SensedHal;
- PilController: the firmware on a virtual board under MicroPython
  (processor in the loop): readings and outputs travel as frames over its
  hardware link, commands over its serial port;
- ReplayController: a recording's current references, open loop;
- IdleController: zero currents (a robot that is switched off).

SIL and PIL feed the firmware the same bytes in the same cycles, so in
fixed-step mode they give the same trajectory bit for bit.
"""
from __future__ import annotations

import socket
import struct
import time
from dataclasses import dataclass
from pathlib import Path

from firmware.hal_sensed import SensedHal
from protocol import messages as M
from protocol.framing import FrameDecoder, FrameEncoder

RULE_SETS = {"first": 0, "refined": 1}


@dataclass
class Sense:
    tick_ms: int
    adc_off: list[int]
    adc_on: list[int]
    enc_l: int
    enc_r: int
    vbat_mv: int


@dataclass
class Actuate:
    i_left_ma: int
    i_right_ma: int
    emitter_pct: int


def setup_frames(rule_set: int, mode: int = M.MODE_AUTONOMOUS) -> list[bytes]:
    """What the host says before the first cycle: the rule set, then the mode."""
    enc = FrameEncoder()
    return [
        enc.encode(M.PARAM_SET, M.pack_payload(M.PARAM_SET, {"param": M.param_by_name("rule_set")[0],
                                                               "value": rule_set})),
        enc.encode(M.COMMAND, M.pack_payload(M.COMMAND, {"mode": mode, "left": 0, "right": 0})),
    ]


class _SilHal(SensedHal):
    """SensedHal with an in-process host link."""

    def __init__(self) -> None:
        SensedHal.__init__(self)
        self.inbox = bytearray()
        self.outbox = bytearray()

    def wait_cycle(self, period_ms: int) -> int:
        return self.tick

    def host_read(self, buf: bytearray) -> int:
        n = min(len(buf), len(self.inbox))
        buf[:n] = self.inbox[:n]
        del self.inbox[:n]
        return n

    def host_write(self, data: memoryview) -> None:
        self.outbox += data

    def end_cycle(self) -> None:
        pass


class SilController:
    name = "SIL"

    def __init__(self, rule_set: int = 1) -> None:
        from firmware.robot import Robot

        self.hal = _SilHal()
        self.robot = Robot(self.hal)
        for frame in setup_frames(rule_set):
            self.hal.inbox += frame

    def cycle(self, s: Sense) -> Actuate:
        hal = self.hal
        hal.begin()
        hal.tick = s.tick_ms
        hal.adc_off[:] = s.adc_off
        hal.adc_on[:] = s.adc_on
        hal.enc[0] = s.enc_l
        hal.enc[1] = s.enc_r
        hal.vbat = s.vbat_mv
        self.robot.run(1)  # with the firmware's own fault handling
        return Actuate(hal.i_left, hal.i_right, hal.power_used)

    def telemetry(self) -> list[dict[str, object]]:
        """TELEMETRY the firmware sent since the last call."""
        frames = FrameDecoder().decode_all(bytes(self.hal.outbox))
        self.hal.outbox.clear()
        return [M.unpack_payload(t, p) for t, _s, p in frames if t == M.TELEMETRY]

    def close(self) -> None:
        pass


class PilLink:
    """The simulator's end of a virtual board's hardware link (TCP on 127.0.0.1)."""

    def __init__(self) -> None:
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
        payload = struct.pack(M.FORMATS[M.HW_SENSE], s.tick_ms & 0x3FFFFFFF, *s.adc_off, *s.adc_on,
                              s.enc_l, s.enc_r, s.vbat_mv)
        self.conn.sendall(self.enc.encode(M.HW_SENSE, payload))
        dec = self.dec
        while True:
            try:
                data = self.conn.recv(4096)
            except socket.timeout:
                raise RuntimeError("the virtual board did not answer HW_SENSE within 10 s") from None
            if not data:
                raise RuntimeError("the virtual board closed its hardware link (it stopped or was reset)")
            i, end = 0, len(data)
            while i < end:
                i = dec.feed(data, i, end)
                if dec.ready and dec.msg_type == M.HW_ACTUATE:
                    _tick, il, ir, pct = struct.unpack_from(M.FORMATS[M.HW_ACTUATE], dec.body, 3)
                    return Actuate(il, ir, pct)

    def close(self) -> None:
        if self.conn:
            self.conn.close()
        self.server.close()


class PilController:
    """The firmware on a virtual board; this process is its hardware and its host."""

    name = "PIL"

    def __init__(self, rule_set: int = 1, flash_dir: Path | None = None, log: Path | None = None) -> None:
        import tempfile

        from host_sim.virtual_board import VirtualBoard, factory_image
        from tools.serial_link import SerialLink

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
            for frame in setup_frames(rule_set):
                self.host.send_raw(frame)
            time.sleep(0.2)  # the commands wait in the board's input before cycle 0
        except Exception:
            self.close()
            raise

    def cycle(self, s: Sense) -> Actuate:
        return self.link.exchange(s)

    def telemetry(self) -> list[dict[str, object]]:
        frames: list[dict[str, object]] = []
        while True:
            got = self.host.poll(0.05)
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


class ReplayController:
    """A recording's current references, one row per cycle (open loop)."""

    name = "replay"

    def __init__(self, cmd_amps: list[tuple[float, float]], emitter_pct: int = 60) -> None:
        self.cmd = cmd_amps
        self.k = 0
        self.emitter_pct = emitter_pct

    def cycle(self, s: Sense) -> Actuate:
        if self.k < len(self.cmd):
            left, right = self.cmd[self.k]
        else:
            left = right = 0.0
        self.k += 1
        return Actuate(round(left * 1000), round(right * 1000), self.emitter_pct)

    def close(self) -> None:
        pass


class IdleController:
    name = "idle"

    def cycle(self, s: Sense) -> Actuate:
        return Actuate(0, 0, 0)

    def close(self) -> None:
        pass
