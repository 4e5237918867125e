"""Ctrl-C that is never lost: a SIGINT swallowed inside a guard is raised again by ``check``, ``clear`` forgets it,
the handler in place before the guard is called and put back, and errors pass through a guard when SIGINT is
ignored. A solve stopped this way is tested in tests/dem/test_scene.py."""

import signal

import pytest

from jaxbpm import _interrupt
from jaxbpm.errors import SceneError


@pytest.fixture
def python_handler():
    """Python's own SIGINT handler, as in an interactive session (a suite started with SIGINT ignored would never
    see the signal)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _swallow_sigint():
    try:
        signal.raise_signal(signal.SIGINT)
    except KeyboardInterrupt:  # as a garbage-collection callback drops it
        pass


def test_a_swallowed_interrupt_is_raised_again_once(python_handler):
    _interrupt.check()  # nothing pending outside a guard
    with _interrupt.guard():
        _interrupt.check()  # nor before a signal
        _swallow_sigint()
        with pytest.raises(KeyboardInterrupt):
            _interrupt.check()
        _interrupt.check()  # delivered: forgotten
        _swallow_sigint()
        _interrupt.clear()
        _interrupt.check()  # cleared: forgotten
        _swallow_sigint()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back on leaving
    _interrupt.check()  # and the memory goes with the guard


def test_nested_guards_share_one_handler_and_the_previous_one_is_called(python_handler):
    seen = []

    def own(sig, frame):
        seen.append(sig)

    signal.signal(signal.SIGINT, own)
    with _interrupt.guard():
        handler = signal.getsignal(signal.SIGINT)
        assert handler is not own
        with _interrupt.guard():
            assert signal.getsignal(signal.SIGINT) is handler
            with pytest.raises(KeyboardInterrupt):
                signal.raise_signal(signal.SIGINT)
        assert seen == [signal.SIGINT]  # the handler that was there still hears the signal
        assert signal.getsignal(signal.SIGINT) is handler  # the inner guard left it alone
        with pytest.raises(KeyboardInterrupt):
            _interrupt.check()
    assert signal.getsignal(signal.SIGINT) is own


def test_guard_lets_errors_through_when_interrupts_are_ignored():
    # started with SIGINT ignored (`nohup`, `&` in a script): an error raised inside the guard is that error, not
    # "generator didn't stop after throw()" (a SceneError is a ValueError, which the guard's set-up once caught)
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with pytest.raises(SceneError, match="bad scene"):
            with _interrupt.guard():
                raise SceneError("bad scene")
    finally:
        signal.signal(signal.SIGINT, old)
