"""Futures of the link's answers: one made done, one converted when another is done."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from typing import Any


def done(value: Any) -> Future:
    """A Future that is already done with ``value``."""
    future: Future = Future()
    future.set_result(value)
    return future


def then(future: Future, convert: Callable[[Any], Any]) -> Future:
    """A Future of ``convert(result)`` once ``future`` is done; ``future``'s exception, or
    one ``convert`` raised, passed on instead."""
    out: Future = Future()

    def finish(finished: Future) -> None:
        error = finished.exception()
        if error is not None:
            out.set_exception(error)
            return
        try:
            out.set_result(convert(finished.result()))
        except Exception as exc:  # a conversion bug: the caller sees it, never a thread
            out.set_exception(exc)

    future.add_done_callback(finish)
    return out
