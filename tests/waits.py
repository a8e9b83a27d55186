"""Polling for a condition in tests that wait on other threads or processes."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_until(cond: Callable[[], object], timeout: float = 5.0, poll: float = 0.02) -> bool:
    """Poll ``cond()`` until it is truthy (True) or ``timeout`` seconds pass (its last value)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(poll)
    return bool(cond())
