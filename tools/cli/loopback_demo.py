"""`twinbot demo --loopback`: the serial protocol, shown on its own (protocol/SPEC.md).

A scripted robot conversation (HELLO, parameters, COMMANDs, TELEMETRY, a LOG) goes out
through the serial harness on loop:// and comes back decoded, with one frame corrupted on
the way and one dropped, so the counters show what the decoder catches.  Every frame is
recorded to a frame log (docs/frame-log.md).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from protocol import messages as M
from host_sim.board.frame_log import FrameLogWriter, read_frame_log
from firmware import config
from tools.cli.serial_harness import Display, status_text
from host_sim.board.serial_link import Frame, SerialLink


def script() -> list[tuple[int, dict[str, object]]]:
    """What a robot and its host say in the first second of a session."""
    out: list[tuple[int, dict[str, object]]] = [
        (M.HELLO, {"protocol": M.PROTOCOL_VERSION, "fw_major": config.FIRMWARE_VERSION[0],
                   "fw_minor": config.FIRMWARE_VERSION[1], "fw_patch": config.FIRMWARE_VERSION[2],
                   "board": M.BOARD_VIRTUAL, "sensors": 8, "wheel_diameter_um": config.WHEEL_DIAMETER_UM,
                   "wheel_base_um": config.WHEEL_BASE_UM, "ticks_per_rev": config.TICKS_PER_REV}),
        (M.PARAM_SET, {"param": M.param_by_name("emitter_pct")[0], "value": 80}),
        (M.PARAM_VALUE, {"param": M.param_by_name("emitter_pct")[0], "value": 80}),
        (M.COMMAND, {"mode": M.MODE_HOST, "left": 150, "right": 120}),
    ]
    for k in range(10):
        near = 40 * k
        out.append((M.TELEMETRY, {
            "tick_ms": 40 * k, "mode": M.MODE_HOST, "flags": 0, "enc_l": 9 * k, "enc_r": 7 * k,
            "ir_on": [300 + near, 250, 120, 90, 80, 95, 130, 260 + near], "ir_amb": [60, 55, 50, 48, 47, 49, 52, 58],
            "i_ref_l_ma": 120, "i_ref_r_ma": 100, "vbat_mv": 7400 - k, "sp_l": 150, "sp_r": 120,
            "odo_x": 4000 * k, "odo_y": 0, "odo_heading": 0, "emitter_pct": 80,
        }))
    out.append((M.LOG, {"level": M.LOG_INFO, "text": "demo: obstacle ahead, slowing down"}))
    return out


def run(args: argparse.Namespace) -> int:
    """args: record (frame log path), port (default loop://)."""
    Path(args.record).parent.mkdir(parents=True, exist_ok=True)
    log = FrameLogWriter(args.record, args.port)
    display = Display(quiet=False)

    def on_frame(frame: Frame) -> None:
        log.frame(frame)
        if frame.direction == "rx":
            display.frame(frame)

    link = SerialLink.open(args.port, on_frame=on_frame)
    display.link = link
    print(f"twinbot demo: {len(script())} frames out through {args.port} and back; frame 6 is corrupted on the way, "
          "frame 9 is dropped")
    try:
        for k, (msg_type, fields) in enumerate(script()):
            payload = M.pack_payload(msg_type, fields)  # type: ignore[arg-type]
            raw = link.encoder.encode(msg_type, payload)
            if k == 6:
                raw = raw[:10] + bytes([raw[10] ^ 0x04]) + raw[11:]  # one flipped bit: the CRC must catch it
            if k == 9:
                continue  # never sent: the sequence numbers show the gap
            link.send_raw(raw)
            link.poll(0.01)
        while link.poll(0.05):
            pass
    finally:
        log.stats(link.now(), link.decoder.stats())
        log.close()
        link.close()
    print("\n" + status_text(link) if display.tty else status_text(link))
    records = read_frame_log(args.record)
    print(f"frame log: {args.record} ({len(records)} records, re-read and verified)")
    return 0
