"""Ctrl-C that cannot be lost: a SIGINT handler that also remembers the request.

Python delivers SIGINT as a KeyboardInterrupt at the next bytecode of the main thread.
When that bytecode belongs to a garbage-collector callback or a ``__del__`` (Dask's
``GCDiagnosis`` runs one), the exception is printed as "ignored" and the program goes on
as if no Ctrl-C had come. The handler here raises as Python's does and also records the
request, which long loops (the dataset runner) and the command line check.
"""

import contextlib
import signal
import threading

__all__ = ["check", "installed", "requested"]

_requested = False


def _handler(signum, frame):
    global _requested
    _requested = True
    raise KeyboardInterrupt


def requested():
    """Whether a Ctrl-C came since the handler was installed."""
    return _requested


def check():
    """Raise KeyboardInterrupt if a Ctrl-C came (and was perhaps swallowed on its way)."""
    if _requested:
        raise KeyboardInterrupt


@contextlib.contextmanager
def installed():
    """The handler in place of Python's default one while the block runs.

    Nothing changes outside the main thread, nor when SIGINT is not at Python's default
    (ignored by a parent, or handled by the caller).
    """
    global _requested
    _requested = False
    previous = None
    if (
        threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    ):
        previous = signal.signal(signal.SIGINT, _handler)
    try:
        yield
    finally:
        if previous is not None and signal.getsignal(signal.SIGINT) is _handler:
            signal.signal(signal.SIGINT, previous)
