"""What goes on the board: the one list every tool that builds a board reads (docs/firmware.md).

`twinbot flash` compiles BOARD_FILES to .mpy and copies them with main.py; the virtual
board's factory image holds them as sources; `twinbot bench firmware` measures the heap
with them loaded.  Every .py under firmware/ and protocol/ is named here exactly once
(tests/test_layers.py::test_manifest_names_every_micropython_module_once).
Paths are relative to the repository root, with '/' separators.
"""

# The robot's firmware and the protocol it speaks.
BOARD_FILES = (
    "protocol/__init__.py",
    "protocol/compat.py",
    "protocol/cobs.py",
    "protocol/crc16.py",
    "protocol/fields.py",
    "protocol/framing.py",
    "protocol/messages.py",
    "protocol/wire.py",
    "firmware/__init__.py",
    "firmware/config.py",
    "firmware/trig.py",
    "firmware/fuzzy.py",
    "firmware/ir.py",
    "firmware/odometry.py",
    "firmware/wheels.py",
    "firmware/stall.py",
    "firmware/hal.py",
    "firmware/hal_buffered.py",
    "firmware/hal_rp2040.py",
    "firmware/hal_sim_link.py",
    "firmware/hostlink.py",
    "firmware/robot.py",
    "firmware/main.py",
)

# Run under MicroPython but never flashed: the virtual board's boot (it
# lives outside the board's flash, as a chip's boot ROM does) and the HAL
# of the tests and benchmarks.
OFF_BOARD_FILES = (
    "firmware/unix_board.py",
    "firmware/hal_testbench.py",
    "firmware/manifest.py",
)

# What a board's /main.py says.
MAIN_PY = "import firmware.main\nfirmware.main.start()\n"
