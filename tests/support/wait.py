"""Condition-based waiting for tests: poll, and fail saying what was waited for."""

from __future__ import annotations

import time
from collections.abc import Callable

WAIT_S = 30.0  # generous bound for convergence on a loaded 2-core machine; not a timing test


def wait_for(condition: Callable[[], bool], what: str, timeout_s: float = WAIT_S) -> None:
    """Poll ``condition`` until true; fail naming ``what`` if it never becomes true."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if condition():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")
