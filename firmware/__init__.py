"""twinbot firmware: runs on the robot (RP2040), on the virtual board and in the simulator.

MicroPython-compatible and dependency-free beyond MicroPython's built-ins and the shared
protocol package; firmware/manifest.py lists what goes on a board (docs/firmware.md).
"""
