"""A log's pairs registered in a process of their own, ahead of its tracks.

A frame's work is the pair's registration (about two thirds of it) and the tracks' steps
on the pair's fit. The pairs need nothing of the tracks (:mod:`mmreg.tracking._pairs`),
so with two cores :class:`PairProcess` registers the next pairs while this process runs
the tracks on the last one: the two halves of the work overlap, and the fits are those
that the chain gives in this process. The worker takes a second or two to start (it
imports scikit-learn); until it is :meth:`~PairProcess.ready`, this process registers
the pairs itself, and then sends it the chain as it stands. A worker whose log ended
with every fit taken waits for the next log of this process (as joblib keeps its
workers), for ten minutes at most.

The worker is a new interpreter (a fork would copy the thread pools of Open3D and
small_gicp, which deadlocks), started by loky (joblib's, so scikit-learn's) as it starts
joblib's workers: it does not import the user's script, which needs no
``if __name__ == "__main__":`` guard.
"""

import contextlib
import multiprocessing
import pickle
import queue
import signal
import threading
import time
import traceback
import weakref

from joblib.externals.loky.backend.context import get_context

from mmreg._array.threads import single_threaded_blas
from mmreg._warnings import warn

__all__ = ["PairProcess", "PairsAhead"]

# Seconds between looks at whether the worker still runs while waiting for its fit.
_POLL = 1.0
# Frames sent to the worker whose fits the tracks have not taken yet: with one, the worker
# registers the next pair while the tracks take the last.
_FRAMES_AHEAD = 1
# A worker waits this long for a next log, and is given one only within half of it.
_IDLE_SECONDS = 600.0
# The message that ends a log (the worker then waits for the next log's chain).
_END_LOG = b""
# The worker whose log ended with every fit taken, and since when it waits.
_idle = []
_idle_lock = threading.Lock()


class PairsAhead:
    """A log's frames through its :class:`~mmreg.tracking._log.LogTracker`, the pairs
    registered in a :class:`PairProcess` once it has started (before, and with fewer
    than two ``processes``, in this process).

    A frame's results come :data:`_FRAMES_AHEAD` frames later than the tracker alone
    gives them, once the pairs are the worker's; they are the same results.

    Parameters
    ----------
    tracker : LogTracker
        A new log's.
    processes : int
        2 or more: the pairs in a process of their own. Inside a daemonic process (a
        Dask worker's), which may not start one, they stay in this one.
    """

    def __init__(self, tracker, processes):
        self.tracker = tracker
        apart = processes >= 2 and not multiprocessing.current_process().daemon
        self._process = (_idle_worker() or PairProcess()) if apart else None
        self._owed = 0  # fits of pairs sent that the worker has not given yet
        self._remote = False  # whether the pairs are the worker's
        self._waiting = []  # frames sent to the worker, not yet added
        self._previous = None
        self.n_frames = 0  # frames given

    def add(self, points, time=None, pose=None, point_times=None):
        """Add the next frame (as :meth:`LogTracker.step`); the results (Bunches) of the
        frames it makes final."""
        with self._cores():
            return self._add(points, time, pose, point_times)

    def _cores(self):
        # With the two processes on the cores, a second BLAS thread in either only waits.
        return single_threaded_blas() if self._process is not None else contextlib.nullcontext()

    def _add(self, points, time, pose, point_times):
        frame = self.tracker.new_frame(self.n_frames, points, time, pose, point_times)
        previous = self._previous
        if previous is not None and frame.time <= previous.time:
            raise ValueError(f"frame {frame.index}: its time does not follow the last frame's.")
        process = self._process
        if process is not None and not self._remote and previous is not None and process.ready():
            # The pairs from (previous, frame) on are the worker's, if it can take them.
            self._remote = process.start(self.tracker.pairs)
            if self._remote:
                process.send(previous)
            else:
                self._process = None
        self._previous = frame
        self.n_frames += 1
        if not self._remote:
            return self.tracker.add(frame)
        process.send(frame)
        self._owed += 1
        self._waiting.append(frame)
        results = []
        while len(self._waiting) > _FRAMES_AHEAD:
            results.extend(self.tracker.add(self._waiting.pop(0), self._receive()))
        return results

    def _receive(self):
        fit = self._process.receive()
        self._owed -= 1
        return fit

    def close(self):
        """End the log: the results of every frame still pending; the worker ends."""
        try:
            with self._cores():
                results = []
                while self._waiting:
                    fit = self._receive()
                    results.extend(self.tracker.add(self._waiting.pop(0), fit))
                return results + self.tracker.close()
        finally:
            self.end()

    def end(self):
        """Let the worker go: to wait for this process's next log if it owes no fit,
        else it ends (the log stopped on an error)."""
        process, self._process = self._process, None
        if process is None:
            return
        if self._owed or not process.alive():
            process.close()
            return
        process.end_log()
        with _idle_lock:
            _idle.append((process, time.monotonic()))
            while len(_idle) > 1:
                _idle.pop(0)[0].close()


def _idle_worker():
    """A worker that waits for a next log and will for a while yet, or None."""
    with _idle_lock:
        while _idle:
            process, since = _idle.pop()
            if time.monotonic() - since < _IDLE_SECONDS / 2 and process.alive():
                return process
            process.close()
    return None


class PairProcess:
    """A process that registers the pairs of the frames it is sent, in order.

    Examples
    --------
    Once :meth:`ready`, ``process.start(chain)`` (the log's
    :class:`~mmreg.tracking._pairs.PairChain` as it stands), ``process.send(frame)`` for
    the last frame registered and each frame after it
    (:class:`~mmreg.tracking._log.LogFrame`), and ``process.receive()`` for each pair's
    :class:`~mmreg.tracking._pairs.PairFit`, in order; use it as a context manager, which
    ends the worker.
    """

    def __init__(self):
        context = get_context("loky")
        self._frames = context.Queue()  # its feeder thread sends them: no wait here
        # The fits come through a pipe whose writing end only the worker holds: if it
        # dies, even halfway through a fit, the reading end here reads the end of it.
        self._fits, writer = context.Pipe(duplex=False)
        self._ready = context.Event()
        self._process = context.Process(
            target=_serve, args=(self._frames, writer, self._ready), daemon=True
        )
        self._process.start()
        writer.close()
        # A log left unfinished (an online log dropped, an error) ends its worker too.
        self._ending = weakref.finalize(self, _end, self._process, self._frames, self._fits)

    def ready(self):
        """Whether the worker has started and waits for the chain."""
        return self._ready.is_set()

    def alive(self):
        """Whether the worker runs."""
        return self._process.is_alive()

    def end_log(self):
        """End the log: the worker drops its chain and last frame, and waits for the
        next log's chain."""
        self._frames.put(_END_LOG)

    def start(self, chain):
        """Give the worker the chain, which it continues from where it stands; whether
        it took it (if not, a warning says why, and the worker ends)."""
        self._frames.put(_dumps(chain))
        try:
            self.receive()
        except Exception as error:  # a pair estimator it cannot rebuild, say
            warn(f"the log's pairs stay in this process: {error!r}", RuntimeWarning)
            self.close()
            return False
        return True

    def send(self, frame):
        """Give the worker the next frame (it keeps the last one, for the next pair)."""
        # Pickled here and now: a queue pickles in a thread of its own, later, and the
        # frame may have changed by then.
        self._frames.put(_dumps(frame.for_pairs()))

    def receive(self):
        """The next pair's fit; raises what the worker raised."""
        try:
            while not self._fits.poll(_POLL):
                if not self._process.is_alive():
                    raise EOFError
            kind, value = pickle.loads(self._fits.recv_bytes())
        except (EOFError, OSError):
            self._process.join(timeout=_POLL)
            raise RuntimeError(
                "the process registering the log's pairs ended unexpectedly "
                f"(exit code {self._process.exitcode})."
            ) from None
        if kind == "error":
            error, text = value
            raise error from _RemoteTraceback(text)
        return value

    def close(self):
        """End the worker (at once, if it is still busy)."""
        self._ending()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _end(process, frames, fits):
    if process.is_alive():
        frames.put(None)
        process.join(timeout=_POLL)
    if process.is_alive():
        process.terminate()
        process.join()
    frames.cancel_join_thread()  # what the worker did not read is not needed
    frames.close()
    fits.close()


class _RemoteTraceback(Exception):
    """The worker's traceback, as the cause of what it raised."""

    def __str__(self):
        return "\n" + self.args[0]


def _serve(frames, fits, ready):
    """The worker: the chain, then frames; each after the first makes a pair with the
    one before."""
    # A Ctrl-C reaches the whole process group: this process leaves it to its parent,
    # which ends it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import mmreg.tracking._pairs  # noqa: F401  (what unpickling the chain imports)

    ready.set()
    with single_threaded_blas():
        while True:
            try:
                message = frames.get(timeout=_IDLE_SECONDS)
            except queue.Empty:  # no next log: the parent starts another worker if any
                return
            if message is None:
                return
            if message == _END_LOG:  # a log that ended before its pairs came here
                continue
            try:
                chain = pickle.loads(message)
            except Exception as error:
                _report(fits, error)
                return
            fits.send_bytes(_dumps(("started", None)))
            if not _fit_pairs(chain, frames, fits):
                return


def _fit_pairs(chain, frames, fits):
    """Fit the pairs of the frames that come, until the log ends (True) or the worker
    must (False: told to, or a fit failed)."""
    previous = None
    while (message := frames.get()) != _END_LOG:
        if message is None:
            return False
        frame = pickle.loads(message)
        if previous is not None:
            try:
                fits.send_bytes(_dumps(("fit", chain.fit_apart(previous, frame))))
            except BaseException as error:  # to the caller, who raises it
                _report(fits, error)
                return False
        previous = frame
    return True


def _report(fits, error):
    """Send ``error`` with its traceback to the caller."""
    text = traceback.format_exc()
    try:
        message = _dumps(("error", (error, text)))
    except Exception:  # an error that does not pickle
        message = _dumps(("error", (RuntimeError(repr(error)), text)))
    fits.send_bytes(message)


def _dumps(value):
    return pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
