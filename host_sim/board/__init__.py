"""The board and the link: MicroPython, the virtual board, PIL, the serial link and frame logs (docs/firmware.md)."""
