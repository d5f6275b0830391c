"""Shared fixtures."""
from __future__ import annotations

import pytest

from tests.helpers import Pty


@pytest.fixture
def pty_pair():
    """A real pseudo-terminal pair, closed after the test."""
    p = Pty()
    yield p
    p.close()
