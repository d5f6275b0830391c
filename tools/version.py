"""The package's version: one source, pyproject.toml's `version`, read through importlib.metadata.

The host's HELLO and `twinbot --version` use it; the firmware carries the same number in
firmware/config.py FIRMWARE_VERSION, because a board cannot read the host's package metadata
(tests/test_cli_commands.py::test_version_is_the_package_version_and_the_firmware_carries_the_same).
"""
from __future__ import annotations

import re
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"


def package_version() -> str:
    """The installed package's version; pyproject.toml's when running from a checkout that is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("twinbot")
    except PackageNotFoundError:
        return pyproject_version()


def pyproject_version() -> str:
    import tomllib

    with open(PYPROJECT, "rb") as f:
        return str(tomllib.load(f)["project"]["version"])


def version_triple(text: str | None = None) -> tuple[int, int, int]:
    """(major, minor, patch) of a version such as '0.2.0' or '0.2.0.dev1' (HELLO's three bytes)."""
    m = re.match(r"(\d+)\.(\d+)(?:\.(\d+))?", text or package_version())
    if not m:
        return (0, 0, 0)
    return int(m.group(1)) & 0xFF, int(m.group(2)) & 0xFF, int(m.group(3) or 0) & 0xFF
