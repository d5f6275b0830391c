"""The virtual board's "ROM": what a real board's MicroPython does around main.py (docs/firmware.md).

Run by `twinbot board` under the MicroPython unix port, stdin/stdout wired to a
pseudo-terminal: its own flash mounted at "/", main.py after every reset, the friendly
and the raw REPL that mpremote drives, Ctrl-D and machine.reset().

usage: micropython firmware/unix_board.py FLASH, where FLASH is a folder or IMAGE_FILE:SIZE_KB
(a littlefs image, created blank when missing); TWINBOT_HW=host:port names the simulator.
"""
import io
import os
import sys

import vfs

_BANNER = "MicroPython {} on twinbot virtual board (unix port); type help() for help\r\n".format(
    ".".join(str(v) for v in sys.implementation.version[:3]))
_RAW_PROMPT = b"raw REPL; CTRL-B to exit\r\n>"
_IN = sys.stdin.buffer
_OUT = sys.stdout.buffer


class HardReset(Exception):
    """machine.reset() was called."""


class SoftReset(Exception):
    """machine.soft_reset() was called."""


class PowerOff(Exception):
    """The host side of the serial port hung up."""


class _Machine:
    """The machine module as code on the board sees it: the unix port's,
    plus reset() and soft_reset(), which a unix process otherwise lacks."""

    def __init__(self, real: object) -> None:
        self._real = real

    def reset(self) -> None:
        raise HardReset()

    def soft_reset(self) -> None:
        raise SoftReset()

    def __getattr__(self, name: str) -> object:
        return getattr(self._real, name)


class FileBlockDevice:
    """A littlefs block device in a host file: the board's flash chip."""

    BLOCK = 4096

    def __init__(self, path: str, size_kb: int) -> None:
        self.blocks = size_kb * 1024 // self.BLOCK
        try:
            self.f = open(path, "r+b")
            self.fresh = False
        except OSError:
            self.f = open(path, "w+b")
            self.f.write(b"\xff" * (self.blocks * self.BLOCK))
            self.f.flush()
            self.fresh = True

    def readblocks(self, block: int, buf: bytearray, offset: int = 0) -> None:
        self.f.seek(block * self.BLOCK + offset)
        self.f.readinto(buf)

    def writeblocks(self, block: int, buf: bytearray, offset: int = 0) -> None:
        self.f.seek(block * self.BLOCK + offset)
        self.f.write(buf)
        self.f.flush()

    def ioctl(self, op: int, arg: int) -> int:
        if op == 4:  # block count
            return self.blocks
        if op == 5:  # block size
            return self.BLOCK
        if op == 6:  # erase
            self.f.seek(arg * self.BLOCK)
            self.f.write(b"\xff" * self.BLOCK)
            return 0
        return 0


def mount_flash(spec: str) -> None:
    """Mount the board's flash at "/" and make it the only place to import from."""
    if ":" in spec and not spec.endswith(":"):
        path, size = spec.rsplit(":", 1)
        dev = FileBlockDevice(path, int(size))
        # (The rp2 stubs this file is checked against know neither a Python
        # block device nor the unix port's VfsPosix.)
        if dev.fresh:
            vfs.VfsLfs2.mkfs(dev)  # type: ignore[arg-type]
        fs: object = vfs.VfsLfs2(dev)  # type: ignore[abstract,arg-type]
    else:
        fs = vfs.VfsPosix(spec)  # type: ignore[attr-defined]
    vfs.umount("/")
    vfs.mount(fs, "/")
    os.chdir("/")
    sys.path[:] = ["", "/lib"]


def _write(data: bytes) -> None:
    _OUT.write(data)


def _read_byte() -> int:
    b = _IN.read(1)
    if not b:
        raise PowerOff()
    return b[0]


class Board:
    def __init__(self) -> None:
        import machine

        sys.modules["machine"] = _Machine(machine)  # type: ignore[assignment]
        self.rom_modules = set(sys.modules.keys())
        self.globals: dict[str, object] = {}

    def clear(self) -> None:
        """Forget everything loaded from flash: a reset's fresh start."""
        for name in list(sys.modules.keys()):
            if name not in self.rom_modules:
                del sys.modules[name]
        self.globals = {"__name__": "__main__"}

    def run_main(self) -> None:
        """Boot: run main.py from flash, if there is one, as a board does."""
        try:
            os.stat("main.py")
        except OSError:
            return
        try:
            with open("main.py") as f:
                code = f.read()
            exec(code, self.globals)
        except (HardReset, SoftReset):
            raise
        except SystemExit as exc:
            if type(exc).__name__ == "HardwareGone":
                raise PowerOff()
            raise
        except KeyboardInterrupt:
            pass
        except Exception as exc:  # noqa: BLE001 - shown on the REPL, as a board does
            _write(_traceback(exc))

    def boot(self) -> None:
        while True:
            self.clear()
            try:
                self.run_main()
                self.friendly_repl()
                return
            except (HardReset, SoftReset):
                _write(b"MPY: soft reboot\r\n")

    def friendly_repl(self) -> None:
        _write(_BANNER.encode() + b">>> ")
        line = bytearray()
        while True:
            c = _read_byte()
            if c == 0x01:
                self.raw_repl()
                _write(_BANNER.encode() + b">>> ")
                line = bytearray()
            elif c == 0x02:
                _write(b"\r\n" + _BANNER.encode() + b">>> ")
                line = bytearray()
            elif c == 0x03:
                _write(b"\r\nKeyboardInterrupt\r\n>>> ")
                line = bytearray()
            elif c == 0x04:
                if not line:
                    _write(b"\r\n")
                    raise SoftReset()
            elif c in (0x0D, 0x0A):
                _write(b"\r\n")
                if line:
                    self.run_line(bytes(line).decode())
                line = bytearray()
                _write(b">>> ")
            elif c in (0x08, 0x7F):
                if line:
                    line = line[:-1]
                    _write(b"\x08 \x08")
            elif c >= 0x20:
                line.append(c)
                _write(bytes((c,)))

    def run_line(self, text: str) -> None:
        try:
            try:
                value = eval(text, self.globals)
                if value is not None:
                    _write(repr(value).encode() + b"\r\n")
            except SyntaxError:
                exec(text, self.globals)
        except (HardReset, SoftReset):
            raise
        except Exception as exc:  # noqa: BLE001
            _write(_traceback(exc))

    def raw_repl(self) -> None:
        """mpremote's protocol: code up to Ctrl-D; "OK", output, 0x04, error, 0x04, ">"."""
        _write(_RAW_PROMPT)
        code = bytearray()
        while True:
            c = _read_byte()
            if c == 0x02:
                _write(b"\r\n")
                return
            if c == 0x01:
                _write(_RAW_PROMPT)
                code = bytearray()
            elif c == 0x03:
                code = bytearray()
            elif c == 0x05 and not code:
                # Raw-paste request (0x05 'A' 0x01): understood, not supported.
                _read_byte()
                _read_byte()
                _write(b"R\x00")
            elif c == 0x04:
                if not code:
                    _write(b"\r\nMPY: soft reboot\r\n")
                    self.clear()  # after a soft reset in raw mode, main.py is not run
                    _write(_RAW_PROMPT)
                    continue
                _write(b"OK")
                error = b""
                try:
                    exec(bytes(code).decode(), self.globals)
                except (HardReset, SoftReset):
                    raise
                except Exception as exc:  # noqa: BLE001
                    error = _traceback(exc)
                _write(b"\x04" + error + b"\x04>")
                code = bytearray()
            else:
                code.append(c)


def _traceback(exc: BaseException) -> bytes:
    buf = io.StringIO()
    sys.print_exception(exc, buf)  # type: ignore[attr-defined]
    return str(buf.getvalue()).replace("\n", "\r\n").encode()


def main() -> None:
    if len(sys.argv) < 2:
        print("usage: micropython firmware/unix_board.py FLASH_DIR | IMAGE:SIZE_KB")
        sys.exit(2)
    mount_flash(sys.argv[1])
    board = Board()
    try:
        board.boot()
    except PowerOff:
        pass


if __name__ == "__main__":
    main()
