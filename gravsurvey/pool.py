"""The process pool behind ``run --jobs N``: Ctrl-C belongs to the parent alone.

A Ctrl-C on a terminal sends SIGINT to the whole process group, and one sent to the parent
alone still leaves half-started workers reading a closed pipe.  Either way a worker printed a
``KeyboardInterrupt`` or ``EOFError`` traceback.  So the pool is created, and its workers
spawned, with SIGINT blocked and deferred in the parent (:func:`sigint_deferred`): the workers
inherit the blocked signal across ``exec`` (and ignore it once they run, in case a platform
does not pass the mask on), and a Ctrl-C that arrives meanwhile is raised once the workers
are started.  When the parent is
interrupted (or fails) the workers are terminated and pending flights cancelled, so the run
ends at once with the one line and exit code 130 of the CLI.  The same technique guards the
start of multiprocessing's own resource tracker.

Inside a process, the linear algebra runs with BLAS on one thread
(:func:`single_threaded_blas`).
"""

from __future__ import annotations

import multiprocessing as mp
import signal
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import contextmanager, nullcontext


def single_threaded_blas():
    """Context in which BLAS (numpy's and scipy's OpenBLAS) runs on one thread.

    gravsurvey's linear algebra is small: a flight's 3 x 3 to 18 x 18 matrices and L-BFGS-B's
    vectors of a few parameters, the grid's dense fits of at most a few thousand points.  BLAS
    threads only add their start and spin-wait, and on a busy 2-core machine they cost the
    identification 0.81 s of CPU against 0.17 s single-threaded (warm 1-h 100 Hz flight, median
    of 3 runs; whole run_survey 2.25 -> 1.61 s CPU; profiles.csv identical) and one 600 x 600
    grid solve 0.83 s against 0.03 s.  Uses threadpoolctl, which scikit-learn (a dependency of
    verde and harmonica) brings.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - scikit-learn (verde, harmonica) brings it
        return nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def ignore_sigint() -> None:
    """Pool initializer: a worker never handles SIGINT (the parent stops the pool)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def sigint_deferred():
    """Hold a Ctrl-C back for the ``with`` block, then hand it to the previous handler.

    SIGINT is blocked in this thread, so processes started inside inherit the block, and in
    the main thread Python's handler is replaced by one that only records the signal: another
    thread of the process that does not block it (numpy's BLAS threads, say) may receive it,
    and Python would otherwise raise ``KeyboardInterrupt`` in the main thread all the same,
    half-way through starting a worker.
    """
    caught = []
    previous = signal.getsignal(signal.SIGINT)
    replaced = False
    if previous not in (signal.SIG_IGN, None):
        try:
            signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
            replaced = True
        except ValueError:  # not the main thread, where Python runs its signal handlers
            pass
    masked = hasattr(signal, "pthread_sigmask")  # not on Windows: the initializer alone
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if masked else None
    try:
        yield
    finally:
        if masked:
            # unblocked while the recorder is still installed: a pending Ctrl-C is recorded
            signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        if replaced:
            signal.signal(signal.SIGINT, previous)
    if caught:
        if callable(previous):
            # Python's own handler raises KeyboardInterrupt, and so does the CLI's unless the
            # run is already unwinding or has published its outputs (then the Ctrl-C is moot)
            previous(signal.SIGINT, None)
        else:
            raise KeyboardInterrupt


class WorkerPool:
    """A spawn-context :class:`~concurrent.futures.ProcessPoolExecutor` whose workers ignore
    Ctrl-C and are terminated when the ``with`` block ends by an exception.

    Parameters
    ----------
    max_workers : int
        Number of worker processes.

    Examples
    --------
    >>> with WorkerPool(2) as pool:                                  # doctest: +SKIP
    ...     futures = pool.submit_all(pow, [(2, 3), (3, 2)])
    """

    def __init__(self, max_workers: int) -> None:
        self.max_workers = max_workers
        self.executor: ProcessPoolExecutor | None = None
        self.children_before: set = set()

    def __enter__(self) -> WorkerPool:
        self.children_before = set(mp.active_children())
        try:
            with sigint_deferred():
                self.executor = ProcessPoolExecutor(
                    max_workers=self.max_workers, mp_context=mp.get_context("spawn"), initializer=ignore_sigint
                )
        except BaseException as exc:  # a Ctrl-C held back while creating it: __exit__ will not run
            self.__exit__(type(exc), exc, exc.__traceback__)
            raise
        return self

    def submit_all(self, fn, calls) -> list[Future]:
        """``fn(*args)`` for every ``args`` in ``calls``; the futures in the same order.

        Submitting spawns the workers, so a Ctrl-C meanwhile is deferred to its end."""
        assert self.executor is not None, "use WorkerPool in a with statement"
        with sigint_deferred():
            return [self.executor.submit(fn, *args) for args in calls]

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.executor is None:
            return
        if exc_type is None:
            self.executor.shutdown(wait=True)
            return
        # interrupted or failed: stop now, not after every submitted flight has run
        workers = set(mp.active_children()) - self.children_before
        for p in workers:
            p.terminate()
        self.executor.shutdown(wait=True, cancel_futures=True)
        for p in workers:
            p.join(5.0)
        # let its queues (and their semaphores) be freed now: an interrupted process may end
        # without the interpreter's shutdown (cli.main), which would otherwise report them leaked
        self.executor = None
