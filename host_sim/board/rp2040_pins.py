"""The twin on the emulated Pico's pins: HW_SENSE / HW_ACTUATE on one side, pin levels and duties on the other.

The emulated board connects to the twin's hardware link (host_sim/board/pil.py's PilLink) as a virtual
board does; the bridge (host_sim/board/rp2040/pins.mjs) turns each HW_SENSE into ADC readings and encoder
edges on the chip's pins and reports the PWM duties the firmware set.  This module holds the pin map
(firmware/config.py) and converts the units both ways (docs/rp2040.md, "The twin on the pins").
"""
from __future__ import annotations

import json
import select
import socket
import threading
import time

from firmware import config
from protocol import messages as M
from protocol.framing import FrameDecoder, FrameEncoder

ADC_GPIO_0 = 26  # GPIO 26..29 are ADC inputs 0..3
ADC_FULL = 4095
ADC_VOLTS_MV = 3300


def pin_map() -> dict[str, object]:
    """The firmware's pins as the bridge takes them (firmware/config.py, firmware/hal_rp2040.py)."""
    return {"mux": list(config.PIN_IR_MUX_SELECT), "ir_adc": config.PIN_IR_ADC - ADC_GPIO_0,
            "battery_adc": config.PIN_BATTERY_ADC - ADC_GPIO_0, "emitter": config.PIN_EMITTERS_PWM,
            "motor_pwm": [config.PIN_MOTOR_L_PWM, config.PIN_MOTOR_R_PWM],
            "motor_dir": [config.PIN_MOTOR_L_DIR, config.PIN_MOTOR_R_DIR],
            "enc_a": [config.PIN_ENC_L[0], config.PIN_ENC_R[0]], "enc_b": [config.PIN_ENC_L[1], config.PIN_ENC_R[1]],
            "mirrored": [False, True]}  # the right motor is mounted mirrored (Rp2040Hal._edge_right)


def _compare_value(value: int, full_scale: int, top_plus_1: int) -> int:
    """The PWM compare value the firmware's duty_u16(value * 65535 // full_scale) sets (MicroPython's rp2
    machine.PWM rounds duty_u16 * (TOP + 1) / 65535 to the nearest count)."""
    duty_u16 = value * 65535 // full_scale
    return (duty_u16 * top_plus_1 + 65535 // 2) // 65535


def value_of_duty(cc: int, top_plus_1: int, full_scale: int) -> int:
    """The firmware's value (mA or %) that set compare value cc: one count apart or more, it is exact
    (tests/test_rp2040.py::test_duties_give_back_the_firmware_s_values)."""
    guess = round(cc * full_scale / top_plus_1)
    for value in sorted(range(max(0, guess - 2), min(full_scale, guess + 2) + 1), key=lambda v: abs(v - guess)):
        if _compare_value(value, full_scale, top_plus_1) == cc:
            return value
    return min(full_scale, guess)


def battery_counts(vbat_mv: int) -> int:
    """ADC counts of the battery divider's output (firmware/hal_rp2040.py battery_mv inverts it)."""
    return min(ADC_FULL, round(vbat_mv * ADC_FULL / (ADC_VOLTS_MV * config.BATTERY_DIVIDER)))


def sense_message(fields: dict) -> dict:  # type: ignore[type-arg]
    """A HW_SENSE's fields as the bridge's readings."""
    return {"sense": {"off": list(fields["adc_off"]), "on": list(fields["adc_on"]),  # type: ignore[call-overload]
                      "enc": [fields["enc_l"], fields["enc_r"]], "battery": battery_counts(int(fields["vbat_mv"]))}}


def actuate_fields(outputs: dict) -> dict:  # type: ignore[type-arg]
    """The bridge's pin outputs of one cycle as HW_ACTUATE's fields."""
    currents = []
    for cc, top_plus_1, reverse in outputs["motor"]:
        ma = value_of_duty(cc, top_plus_1, config.CURRENT_FULL_SCALE_MA)
        currents.append(-ma if reverse else ma)
    pct = value_of_duty(outputs["emitter"][0], outputs["emitter"][1], 100)
    return {"tick_ms": outputs["ms"] & 0x3FFFFFFF, "i_ref_l_ma": currents[0], "i_ref_r_ma": currents[1],
            "emitter_pct": pct}


class PinsCoupler:
    """Joins the bridge's pin socket to the twin's hardware link on 127.0.0.1:hw_port.

    It connects when the firmware's loop first waits for readings after a boot and hangs up at every
    boot, as a virtual board's link does when it resets (the twin then waits for the next session)."""

    def __init__(self, hw_port: int) -> None:
        self.hw_port = hw_port
        self.ours, self.bridge_end = socket.socketpair()
        self.twin: socket.socket | None = None
        self.enc, self.dec = FrameEncoder(), FrameDecoder()
        self.cycles = 0
        self.waiting = False  # the chip is held until the twin's next readings
        self._next_try = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="rp2040 pins", daemon=True)

    def start(self) -> None:
        self.bridge_end.close()  # the bridge's process holds its own copy
        self._thread.start()

    def _serve(self) -> None:
        pending = b""
        while not self._stop.is_set():
            if self.twin is None and self.waiting and time.monotonic() >= self._next_try:
                self._connect()  # the twin hung up while the chip waits: its next session
            sources = [self.ours] + ([self.twin] if self.twin else [])
            ready, _, _ = select.select(sources, [], [], 0.2)
            if self.ours in ready:
                data = self.ours.recv(65536)
                if not data:
                    return
                pending += data
                *lines, pending = pending.split(b"\n")
                for line in lines:
                    self._from_bridge(json.loads(line))
            if self.twin is not None and self.twin in ready:
                self._from_twin()

    def _from_bridge(self, message: dict) -> None:  # type: ignore[type-arg]
        if "boot" in message:
            self._hang_up()
            self.waiting = False
        elif "held" in message:
            self.waiting = True
            if self.twin is None:
                self._connect()
        elif "actuate" in message and self.twin is not None:
            self.waiting = True
            payload = M.pack_payload(M.HW_ACTUATE, actuate_fields(message["actuate"]))
            self.cycles += 1
            try:
                self.twin.sendall(self.enc.encode(M.HW_ACTUATE, payload))
            except OSError:
                self._hang_up()

    def _from_twin(self) -> None:
        assert self.twin is not None
        try:
            data = self.twin.recv(4096)
        except OSError:
            data = b""
        if not data:
            self._hang_up()
            return
        for msg_type, _seq, payload in self.dec.decode_all(data):
            if msg_type == M.HW_SENSE:
                fields = M.unpack_payload(M.HW_SENSE, payload)
                self.ours.sendall(json.dumps(sense_message(fields)).encode() + b"\n")
                self.waiting = False

    def _connect(self) -> None:
        try:
            self.twin = socket.create_connection(("127.0.0.1", self.hw_port), timeout=10)
            self.twin.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError:
            self.twin = None
            self._next_try = time.monotonic() + 1.0

    def _hang_up(self) -> None:
        if self.twin is not None:
            self.twin.close()
            self.twin = None
            self.dec = FrameDecoder()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self._hang_up()
        self.ours.close()
