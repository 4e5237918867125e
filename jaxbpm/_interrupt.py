"""Ctrl-C that is never lost.

Python runs a signal handler between two bytecodes of the main thread, wherever it is. When that is inside a
garbage-collection callback (JAX registers one that runs during most long setups and compilations), the
``KeyboardInterrupt`` the handler raises is printed as "Exception ignored in ..." and dropped: the run goes on.
:func:`guard` installs a handler that also remembers the interrupt, and :func:`check` raises it again at the next
safe point (between setup steps, before every DEM chunk, before a solve returns).
"""

from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["guard", "check", "clear"]

_state = {"active": 0, "pending": False}


def _handler(previous):
    def handle(sig, frame):
        _state["pending"] = True
        if callable(previous) and previous not in (signal.default_int_handler, handle):
            previous(sig, frame)
        raise KeyboardInterrupt

    return handle


@contextlib.contextmanager
def guard():
    """Remember every SIGINT that arrives inside the block (main thread only; nested guards share one handler).
    A ``KeyboardInterrupt`` that leaves the block clears the memory: it has been delivered."""
    if threading.current_thread() is not threading.main_thread() or _state["active"]:
        yield
        return
    # decide first, then yield outside any ``except``: an error raised in the block (a SceneError is a ValueError)
    # must leave it, not be taken for a failed signal set-up
    previous = signal.getsignal(signal.SIGINT)
    installed = False
    if previous not in (signal.SIG_IGN, None):  # (off, or handled outside Python: leave them so)
        try:
            signal.signal(signal.SIGINT, _handler(previous))
            installed = True
        except ValueError:  # not the main interpreter
            pass
    if not installed:
        yield
        return
    _state["active"], _state["pending"] = 1, False
    try:
        yield
    finally:
        _state["active"], _state["pending"] = 0, False
        signal.signal(signal.SIGINT, previous)


def check() -> None:
    """Raise ``KeyboardInterrupt`` if a SIGINT arrived inside the current :func:`guard` and was swallowed."""
    if _state["pending"]:
        _state["pending"] = False
        raise KeyboardInterrupt


def clear() -> None:
    """Forget a remembered SIGINT: the ``KeyboardInterrupt`` was caught and is being handled."""
    _state["pending"] = False
