"""twinbot firmware: runs on the robot (RP2040) and on the virtual board.

MicroPython-compatible and dependency-free beyond MicroPython's built-ins and
the shared protocol package.  (The controller, IR loop, HAL and main loop
arrive with the firmware issue; this package holds only what has landed.)
"""
