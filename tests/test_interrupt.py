"""A Ctrl-C whose KeyboardInterrupt something swallows (a garbage-collector callback) is
still seen: the handler remembers it, and the loops that check it stop."""

import contextlib
import signal

import pytest

from mmreg import _interrupt


@pytest.fixture
def default_sigint():
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_a_swallowed_ctrl_c_is_still_seen(default_sigint):
    with _interrupt.installed():
        assert not _interrupt.requested()
        _interrupt.check()  # nothing to raise yet
        # What a callback whose exceptions are "ignored" does with it:
        with contextlib.suppress(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
        assert _interrupt.requested()
        with pytest.raises(KeyboardInterrupt):
            _interrupt.check()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_ignored_sigint_stays_ignored():
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with _interrupt.installed():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            signal.raise_signal(signal.SIGINT)
            assert not _interrupt.requested()
    finally:
        signal.signal(signal.SIGINT, previous)
