"""Software in the loop: the firmware's own modules, in this process (docs/firmware.md).

The firmware's Robot runs on a BufferedHal whose readings are set from a `Sense` each
cycle and whose host link is a pair of in-process buffers, so the host talks to it in
frames exactly as over a serial port.  SIL and PIL (host_sim/board/pil.py) feed the
firmware the same bytes in the same cycles: in fixed-step mode, the same trajectory.
"""
from __future__ import annotations

from firmware.hal_buffered import BufferedHal
from host_sim.controller.hardware_io import Actuate, Sense, setup_frames, stall_guard_off
from host_sim.physics.params import RobotParams
from protocol import messages as M
from protocol.framing import FrameDecoder


class _InProcessHal(BufferedHal):
    """BufferedHal with an in-process host link."""

    def __init__(self) -> None:
        BufferedHal.__init__(self)
        self.inbox = bytearray()
        self.outbox = bytearray()

    def wait_cycle(self, period_ms: int) -> int:
        return self.tick

    def host_read(self, buf: bytearray) -> int:
        n = min(len(buf), len(self.inbox))
        buf[:n] = self.inbox[:n]
        del self.inbox[:n]
        return n

    def host_write(self, buf: bytearray, n: int) -> None:
        self.outbox += buf[:n]

    def end_cycle(self) -> None:
        pass


class SilController:
    name = "SIL"

    def __init__(self, rule_set: int = 1, params: RobotParams | None = None, *, stall_guard: bool = True) -> None:
        """params: the robot the firmware runs on (its geometry is sent first); None: the firmware's defaults.
        stall_guard=False: the paper's explorer alone, as the paper's experiments ran it (stall_ms = 0;
        docs/firmware.md, "The stall guard")."""
        from firmware.robot import Robot

        self.hal = _InProcessHal()
        self.robot = Robot(self.hal)
        for frame in setup_frames(rule_set, params=params):
            self.hal.inbox += frame
        if not stall_guard:
            self.send(stall_guard_off())

    def send(self, frame: bytes) -> None:
        """Queue a frame from the host; the firmware reads it at its next cycle."""
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

    def telemetry(self, wait: float = 0.0) -> list[dict[str, object]]:
        """TELEMETRY the firmware sent since the last call (in process: nothing to wait for)."""
        frames = FrameDecoder().decode_all(bytes(self.hal.outbox))
        self.hal.outbox.clear()
        return [M.unpack_payload(t, p) for t, _s, p in frames if t == M.TELEMETRY]

    def close(self) -> None:
        pass
