"""Compile the numba kernels of a run on the second core during a cold start (issue 17.4).

A cold ``gravsurvey run`` spends most of its time compiling ~12 kernel entry points one after
the other.  :class:`Precompiler` starts one background process (``python -m
gravsurvey.precompile CLAIMS``) that compiles the entry points of :data:`KERNELS` in the order
a run needs them and writes each to numba's on-disk cache, while the run itself goes on in this
process.  The two share the work through claim files, one per kernel, created exclusively
(``O_CREAT | O_EXCL``) by whichever process takes the kernel first:

* the run, needing a kernel nobody claimed, claims and compiles it itself;
* the run, needing a kernel the background process claimed, waits for its ``.done`` file and
  then loads it from the cache; while it waits it compiles unclaimed kernels itself, from the
  end of the list (the ones it needs last);
* the background process skips kernels the run claimed.

So no kernel is compiled twice and neither process waits for nothing.  Robustness: the
background process is only started when the cache is cold and writable and the run is in one
process (``--jobs 1``); a run never waits for a background process that has exited (crash,
Ctrl-C) nor longer than :data:`WAIT_LIMIT_S` per kernel, and then compiles the kernel itself;
the background process is stopped when the run ends, however it ends, and stops by itself
when the run's process is gone.  numba writes its cache files atomically (temporary file,
then rename), so a process stopped mid-way leaves no broken entry.

:data:`KERNELS` lists the entry points the README quickstart compiles (measured with
``benchmarks/kernel_compiles.py``); a kernel missing from it is compiled by the run as before,
a stale entry costs only background CPU.  ``tests/test_startup.py`` checks the list against the
kernels' current signatures.
"""

from __future__ import annotations

import importlib
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

#: the kernels a run calls from Python, in the order the pipeline needs them:
#: (module, function, argument types as numba writes them)
KERNELS: tuple[tuple[str, str, str], ...] = (
    (
        "gravsurvey.io.mcap.scan",
        "_scan_kernel",
        "Array(uint8, 1, 'C', True), int64, int64, bool, Array(bool, 1, 'C'), bool, bool, "
        "Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(int64, 1, 'C'), "
        "Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(int64, 1, 'C')",
    ),
    (
        "gravsurvey.geodesy",
        "_geodetic_to_ecef_arr",
        "Array(float64, 1, 'C'), Array(float64, 1, 'C'), Array(float64, 1, 'C'), float64, float64, "
        "Array(float64, 2, 'C')",
    ),
    (
        "gravsurvey.geodesy",
        "_gravitation_arr",
        "Array(float64, 2, 'C'), float64, float64, float64, float64, Array(float64, 2, 'C')",
    ),
    (
        "gravsurvey.inm.mechanization",
        "_attitude_kernel",
        "Array(float64, 1, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), Array(float64, 3, 'C')",
    ),
    (
        "gravsurvey.inm.mechanization",
        "mechanize_kernel",
        "Array(float64, 1, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), Array(float64, 1, 'C'), "
        "Array(float64, 1, 'C'), bool, Array(float64, 1, 'C'), Array(float64, 1, 'C'), Array(float64, 2, 'C'), "
        "float64, float64, float64, float64",
    ),
    (
        "gravsurvey.geodesy",
        "_ecef_to_geodetic_arr",
        "Array(float64, 2, 'C'), float64, float64, Array(float64, 2, 'C')",
    ),
    (
        "gravsurvey.inm.errormodel",
        "discretise_kernel",
        "Array(float64, 1, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), "
        "Array(float64, 2, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), Array(float64, 1, 'C'), "
        "Array(float64, 1, 'C'), Array(float64, 3, 'C'), Array(float64, 1, 'C'), Array(int64, 1, 'C'), "
        "Array(float64, 1, 'C')",
    ),
    (
        "gravsurvey.inm.kalman",
        "_filter_loop14",
        "Array(float64, 1, 'C'), Array(float64, 2, 'C'), Array(float64, 3, 'C'), Array(float64, 3, 'C'), "
        "Array(float64, 2, 'C'), Array(float64, 3, 'C'), Array(float64, 3, 'C'), Array(float64, 2, 'C'), "
        "Array(float64, 3, 'C'), Array(float64, 2, 'C'), Array(float64, 3, 'C'), Array(float64, 2, 'C'), "
        "Array(float64, 3, 'C')",
    ),
    (
        "gravsurvey.inm.kalman",
        "_rts_loop14",
        "Array(float64, 2, 'C'), Array(float64, 3, 'C'), Array(float64, 2, 'C'), Array(float64, 3, 'C'), "
        "Array(float64, 3, 'C'), Array(float64, 3, 'C'), bool, Array(float64, 2, 'C'), Array(float64, 3, 'C')",
    ),
    ("gravsurvey.inm.mechanization", "rodrigues", "Array(float64, 1, 'C')"),
)

#: the background process starts with this kernel (then the later ones, then the earlier
#: ones): the run reaches it after reading the data and the mechanization (~5 s), which it
#: compiles itself meanwhile; the estimator kernels from here on are ~75 % of the compilation
WORKER_FIRST = "discretise_kernel"

#: longest wait for one kernel the background process compiles, s (a kernel takes 0.1-10 s);
#: past it the run compiles the kernel itself
WAIT_LIMIT_S = 120.0
_POLL_S = 0.02


def parse_signature(text: str) -> tuple:
    """Argument types from their text in :data:`KERNELS` (numba's own notation, e.g.
    ``"Array(float64, 2, 'C'), bool"``), as a tuple of numba types."""
    from numba.core import types

    names = {"Array": types.Array, "UniTuple": types.UniTuple, "bool": types.boolean}
    for name in ("int64", "int32", "uint8", "float64", "float32", "intp"):
        names[name] = getattr(types, name)
    value = eval(f"({text},)", {"__builtins__": {}}, names)  # noqa: S307 - our own constant, fixed names only
    return tuple(value)


def _dispatcher(module: str, name: str):
    return getattr(importlib.import_module(module), name)


class _Claims:
    """Claim and done files of one cold start, in a private folder of the numba cache."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder

    def claim(self, i: int) -> bool:
        try:
            os.close(os.open(self.folder / f"{i}.claim", os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
            return True
        except FileExistsError:
            return False

    def done(self, i: int) -> None:
        try:
            # the CPU seconds this process had used: the cold-start benchmark's time line
            (self.folder / f"{i}.done").write_text(f"{time.process_time():.3f}")
        except OSError:  # folder removed: the run has ended, nobody waits
            pass

    def is_done(self, i: int) -> bool:
        return (self.folder / f"{i}.done").exists()


class Precompiler:
    """Context manager around a cold run: background compilation plus the wait-or-compile hook.

    Parameters
    ----------
    enabled : bool
        False (warm or no writable cache, several processes): does nothing.
    kernels : sequence of (module, function, signature text), optional
        Default :data:`KERNELS`.
    """

    def __init__(self, enabled: bool, kernels=KERNELS) -> None:
        self.enabled = enabled and bool(os.environ.get("NUMBA_CACHE_DIR"))
        self.kernels = tuple(kernels)
        self.proc: subprocess.Popen | None = None
        self.claims: _Claims | None = None
        self._index: dict = {}
        self._mine: set[int] = set()
        self._original = None
        self._depth = 0
        #: kernels this process waited for (then loaded from the cache), for tests
        self.waited: list[int] = []

    def __enter__(self) -> Precompiler:
        if not self.enabled:
            return self
        try:
            folder = (
                Path(os.environ["NUMBA_CACHE_DIR"]) / f".gravsurvey-precompile-{os.getpid()}-{uuid.uuid4().hex[:8]}"
            )
            folder.mkdir(mode=0o700, parents=True)
        except OSError:  # cache folder unusable after all: run as before
            self.enabled = False
            return self
        self.claims = _Claims(folder)
        self.proc = _start_worker(folder, self.kernels)
        if self.proc is None:
            shutil.rmtree(folder, ignore_errors=True)
            self.enabled = False
            return self
        self._install_hook()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Remove the hook, stop the background process, remove the claim folder."""
        if self._original is not None:
            from numba.core.dispatcher import Dispatcher

            Dispatcher.compile = self._original
            self._original = None
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
            self.proc = None
        if self.claims is not None:
            shutil.rmtree(self.claims.folder, ignore_errors=True)
            self.claims = None

    # -- the hook ---------------------------------------------------------------------------

    def _install_hook(self) -> None:
        from numba.core import sigutils
        from numba.core.dispatcher import Dispatcher

        for i, (module, name, sig) in enumerate(self.kernels):
            try:
                self._index[(module, name, parse_signature(sig))] = i
            except Exception:  # a stale entry: the background process skips it as well
                continue
        original = Dispatcher.compile
        self._original = original
        pre = self

        def compile(disp, sig):
            # numba's own entry to compile-or-load one signature: wait for the background
            # process when it has this kernel in hand, else claim it so it is not compiled twice
            try:
                args, _ = sigutils.normalize_signature(sig)
                i = pre._index.get((disp.py_func.__module__, disp.py_func.__name__, tuple(args)))
            except Exception:
                i = None
            if i is not None and tuple(args) not in disp.overloads and pre.claims is not None:
                if pre.claims.claim(i):
                    pre._mine.add(i)
                elif i not in pre._mine:
                    pre._wait(i)
            pre._depth += 1
            try:
                return original(disp, sig)
            finally:
                pre._depth -= 1

        Dispatcher.compile = compile

    def _wait(self, i: int) -> None:
        """Until kernel ``i`` is in the cache (or the background process is gone), compiling
        unclaimed kernels meanwhile (only outside another compilation)."""
        assert self.claims is not None and self.proc is not None
        t_end = time.monotonic() + WAIT_LIMIT_S
        self.waited.append(i)
        while not self.claims.is_done(i) and self.proc.poll() is None and time.monotonic() < t_end:
            j = self._next_unclaimed() if self._depth == 0 else None
            if j is None:
                time.sleep(_POLL_S)
                continue
            self._mine.add(j)
            module, name, sig = self.kernels[j]
            try:
                _dispatcher(module, name).compile(parse_signature(sig))
            except Exception:  # a stale entry: its caller compiles what it needs
                pass

    def _next_unclaimed(self) -> int | None:
        # from the end of the list: the background process works from the kernel the run
        # needs next, the run takes the ones it needs last (measured: 2 s less waiting than
        # taking the next one, whose compilation then held up the run)
        assert self.claims is not None
        for j in reversed(range(len(self.kernels))):
            if j not in self._mine and not (self.claims.folder / f"{j}.claim").exists() and self.claims.claim(j):
                return j
        return None


def _start_worker(folder: Path, kernels) -> subprocess.Popen | None:
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "gravsurvey.precompile", str(folder), str(len(kernels)), str(os.getpid())],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=dict(os.environ),
        )
    except OSError:
        return None


def worker(folder: Path, count: int, parent: int, kernels=KERNELS) -> int:
    """The background process: compile ``kernels[:count]`` in order, skipping claimed ones.

    Returns the number of kernels this process compiled.
    """
    claims = _Claims(folder)
    n = 0
    kernels = kernels[:count]
    first = next((i for i, k in enumerate(kernels) if k[1] == WORKER_FIRST), 0)
    for i in [*range(first, len(kernels)), *range(first)]:
        module, name, sig = kernels[i]
        if not folder.is_dir() or (parent and os.getppid() != parent):
            break  # the run has ended
        if not claims.claim(i):
            continue
        try:
            _dispatcher(module, name).compile(parse_signature(sig))
            n += 1
        except Exception:  # noqa: S110 - a stale entry: the run compiles what it needs itself
            pass
        finally:
            claims.done(i)
    return n


if __name__ == "__main__":
    # stopped by the run (terminate) or by Ctrl-C on the terminal: end at once, no traceback
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    import gravsurvey  # noqa: F401  (the cache folder the run chose is in the environment)

    worker(Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]))
