"""Atomic writes in one place: single files (``<path>.tmp-<pid>`` + fsync + ``os.replace``), the
output directory's all-or-nothing publication (:class:`OutputTransaction`) and its lock
(:class:`OutputLock`). Every writer of the package writes through :func:`atomic_write_text` /
:func:`atomic_write_bytes`, so a file never appears half-written under its final name.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import math
import os
import re
import shutil
import time
from pathlib import Path

from gravsurvey.errors import GravsurveyError

#: published last by :class:`OutputTransaction` (the commit marker of a run)
SUMMARY_NAME = "summary.json"


class LockedError(GravsurveyError):
    """Another gravsurvey run holds the output directory (exit code 2: a usage conflict)."""

    exit_code = 2


def file_sha256(path) -> str:
    """SHA-256 (hex) of a file's bytes, read in 1-MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def atomic_write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``<path>.tmp-<pid>``, fsync, and rename it onto ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def atomic_write_text(path, text: str) -> None:
    """:func:`atomic_write_bytes` of UTF-8 text."""
    atomic_write_bytes(path, text.encode("utf-8"))


_STAGING_PREFIX = ".staging-"
_MANIFEST = ".gravsurvey-files.json"
#: Inside the staging folder: the previous versions of the published files, for a rollback.
_PREVIOUS = ".previous-versions"


def _fsync_dir(path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def remove_stale_staging(out_dir, *, min_age_s: float = 60.0) -> list[str]:
    """Remove staging directories left by killed runs; return their names.

    A staging directory is stale when nobody holds the ``flock`` on it (the kernel drops a
    dead process's locks, SIGKILL included) and it is either older than ``min_age_s`` or named
    after a process id that no longer exists. Live transactions hold their lock for their
    whole life, so they are never removed.
    """
    out_dir = Path(out_dir)
    removed = []
    if not out_dir.is_dir():
        return removed
    for p in out_dir.iterdir():
        if not (p.name.startswith(_STAGING_PREFIX) and p.is_dir()):
            continue
        try:
            fd = os.open(p, os.O_RDONLY | os.O_DIRECTORY)
        except OSError:
            continue
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue  # a live transaction
            m = re.match(rf"{re.escape(_STAGING_PREFIX)}(\d+)-", p.name)
            dead = False
            if m:
                try:
                    os.kill(int(m.group(1)), 0)
                except ProcessLookupError:
                    dead = True
                except PermissionError:
                    dead = False
            old = time.time() - p.stat().st_mtime > min_age_s
            if dead or old:
                shutil.rmtree(p, ignore_errors=True)
                removed.append(p.name)
        finally:
            os.close(fd)
    return removed


class OutputTransaction:
    """Write a run's outputs into a staging directory and publish them only on success.

    Usage::

        with OutputLock(out), OutputTransaction(out) as tx:
            write_profiles_csv(tx.path("profiles.csv"), table)
            ...
            write_json(tx.path("summary.json"), summary)   # any time; it is published last

    On entry, stale staging directories of killed runs are removed (:func:`remove_stale_staging`)
    and a fresh ``out_dir/.staging-<pid>-<random>/`` is created and ``flock``-ed. Writers write
    there via :meth:`path`. On a clean exit the staged files are published: each is fsync-ed and
    ``os.replace``-d onto its final name in ``out_dir`` (subdirectories kept), in sorted order with
    ``summary.json`` last; then files listed in the previous run's manifest
    (``.gravsurvey-files.json``) but not produced by this run are deleted, the new manifest is
    written (atomically) and the staging directory removed. On an exception the staging
    directory is removed and nothing in ``out_dir`` changes; so does a clean exit that staged no
    file, and an ``OSError`` while publishing (a folder in the way of a file, a file nobody may
    replace, a full disk): the files already renamed go back to their previous versions (hard
    links kept in the staging folder) before it is raised.

    Guarantee (SIGKILL or power loss at any moment): no file is ever visible under its final name
    partly written (every final name is reached by an atomic rename of a complete, fsync-ed file),
    so every output file is either the previous run's complete version or this run's. A kill
    before publishing leaves the previous outputs untouched. A kill *during* publishing can leave
    a mix of new and previous files; ``summary.json`` is renamed last, so it still describes the
    previous run and the mix is detectable (:meth:`file_hashes` lists the SHA-256 of every
    staged file, for the summary to record). The next successful run replaces everything.
    Stale staging directories are removed by the next run. A Ctrl-C (SIGINT) during publishing
    waits for its end (:func:`gravsurvey.pool.sigint_deferred`), then is raised as usual; the CLI
    ignores it then (:data:`gravsurvey.errors.PUBLISHED`).
    """

    def __init__(self, out_dir, *, min_stale_age_s: float = 60.0):
        self.out_dir = Path(out_dir)
        self.staging: Path | None = None
        self._fd = None
        self._min_stale_age_s = min_stale_age_s
        self.published: list[str] = []
        self.removed_stale: list[str] = []

    def __enter__(self) -> "OutputTransaction":
        from gravsurvey.errors import PUBLISHED

        PUBLISHED.clear()
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.removed_stale = remove_stale_staging(self.out_dir, min_age_s=self._min_stale_age_s)
        token = os.urandom(4).hex()
        self.staging = self.out_dir / f"{_STAGING_PREFIX}{os.getpid()}-{token}"
        self.staging.mkdir()
        self._fd = os.open(self.staging, os.O_RDONLY | os.O_DIRECTORY)
        fcntl.flock(self._fd, fcntl.LOCK_EX)
        return self

    def path(self, name) -> Path:
        """Where to write the output ``name`` (a relative path, e.g. ``plots/L01.png``)."""
        if self.staging is None:
            raise RuntimeError("OutputTransaction.path() outside the with-block")
        rel = Path(name)
        if rel.is_absolute() or ".." in rel.parts or not rel.parts:
            raise ValueError(f"output name must be a relative path inside the output directory: {name}")
        p = self.staging / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def staged_files(self) -> list[str]:
        """Relative names of the staged files, publication order (summary.json last)."""
        names = []
        for root, _dirs, files in os.walk(self.staging):
            for f in files:
                if ".tmp-" in f:
                    continue  # a writer's own temporary, never published
                names.append(os.path.relpath(os.path.join(root, f), self.staging))
        names.sort(key=lambda s: (s == SUMMARY_NAME, s))
        return names

    def file_hashes(self) -> dict[str, str]:
        """SHA-256 (hex) of every staged file except summary.json, by relative name."""
        out = {}
        for name in self.staged_files():
            if name == SUMMARY_NAME:
                continue
            out[name] = file_sha256(self.staging / name)
        return out

    def commit(self) -> list[str]:
        """Publish the staged files (see the class docstring); returns their relative names."""
        names = self.staged_files()
        if not names:
            # nothing produced: keep the previous outputs rather than deleting them as obsolete
            self.published = []
            return []
        previous = []
        try:
            previous = json.loads((self.out_dir / _MANIFEST).read_text())["files"]
        except (OSError, ValueError, KeyError, TypeError):
            previous = []
        dirs = set()
        for name in names:
            src = self.staging / name
            with open(src, "rb") as fh:
                os.fsync(fh.fileno())
        _fsync_dir(self.staging)
        # a name that cannot take a file (a folder there) fails before anything is published
        for name in names:
            dst = self.out_dir / name
            if dst.is_dir() and not dst.is_symlink():
                raise IsADirectoryError(errno.EISDIR, "a folder is in the way of an output file", str(dst))
        done = []  # (name, previous version kept in the staging folder, or None)
        try:
            for name in names:
                dst = self.out_dir / name
                if dst.parent != self.out_dir:
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    dirs.add(dst.parent)
                keep = self._keep_previous(dst, name)
                os.replace(self.staging / name, dst)
                done.append((name, keep))
                if name == SUMMARY_NAME:
                    _fsync_dir(self.out_dir)
        except OSError:
            # an error half-way (a file nobody may replace, a full disk): the files already
            # published go back to their previous versions (or away), so the folder is the
            # previous run's, not a mix
            for name, keep in reversed(done):
                try:
                    if keep is not None:
                        os.replace(keep, self.out_dir / name)
                    else:
                        (self.out_dir / name).unlink()
                except OSError:
                    pass
            raise
        for d in dirs:
            _fsync_dir(d)
        for old in previous:
            if isinstance(old, str) and old not in names and ".." not in Path(old).parts:
                try:
                    (self.out_dir / old).unlink()
                except OSError:
                    pass
        atomic_write_text(self.out_dir / _MANIFEST, json.dumps({"files": names}, indent=1) + "\n")
        _fsync_dir(self.out_dir)
        self.published = names
        return names

    def _keep_previous(self, dst: Path, name: str):
        """A hard link (a copy where links fail) of ``dst``'s current version in the staging
        folder, for a rollback; None when there is none. ``dst`` itself stays in place, so a
        kill at any moment leaves every output complete (the previous or the new version)."""
        if not dst.is_file():
            return None
        keep = self.staging / _PREVIOUS / name
        keep.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(dst, keep)
        except OSError:
            shutil.copy2(dst, keep)
        return keep

    def _cleanup(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if self.staging is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging = None

    def __exit__(self, exc_type, exc, tb) -> bool:
        from gravsurvey.errors import INTERRUPT, PUBLISHED
        from gravsurvey.pool import sigint_deferred

        try:
            if exc_type is None:
                if INTERRUPT.is_set():  # a Ctrl-C swallowed on the way: publish nothing
                    raise KeyboardInterrupt
                # a Ctrl-C half-way through the renames would leave new and previous files
                # mixed: it waits for the end of the commit (then the CLI ignores it)
                with sigint_deferred():
                    PUBLISHED.set()
                    self.commit()
        finally:
            self._cleanup()
        return False


class OutputLock:
    """Exclusive lock on an output directory: ``flock`` on ``out_dir/.gravsurvey.lock``.

    The lock file holds the owner's pid (for the message) and is never deleted (deleting a lock
    file races with its next user). The kernel releases the lock when the holder dies, SIGKILL
    included, so there are no stale locks. ``flock`` is per open file: a second OutputLock in the
    same process on the same directory is refused too. Not reliable on some network file systems.

    Parameters
    ----------
    out_dir : path-like
        Created if missing.
    wait : bool
        False (default): refuse at once if another run holds the lock. True: retry every 0.1 s.
    timeout_s : float, optional
        With ``wait``: give up after this long (None: wait forever).
    wait_s : float, optional
        Shorthand for both: 0 refuses at once, > 0 waits up to ``wait_s`` seconds, ``inf``
        waits forever. Overrides ``wait`` and ``timeout_s`` when given.

    Raises
    ------
    LockedError
        ``another gravsurvey run holds <dir> (pid N)`` (exit code 2).
    """

    NAME = ".gravsurvey.lock"

    def __init__(self, out_dir, *, wait: bool = False, timeout_s: float | None = None, wait_s: float | None = None):
        self.out_dir = Path(out_dir)
        if wait_s is not None:  # one-number form: 0 = refuse at once, > 0 = wait that long, inf = forever
            wait = wait_s > 0
            timeout_s = None if math.isinf(wait_s) else float(wait_s)
        self.wait = wait
        self.timeout_s = timeout_s
        self._fd = None

    @property
    def path(self) -> Path:
        return self.out_dir / self.NAME

    def _holder(self) -> str:
        try:
            txt = self.path.read_text().strip()
            return txt if txt.isdigit() else "unknown"
        except OSError:
            return "unknown"

    def acquire(self) -> "OutputLock":
        self.out_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        deadline = None if self.timeout_s is None else time.monotonic() + self.timeout_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as e:
                if e.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    os.close(fd)
                    raise
                if not self.wait or (deadline is not None and time.monotonic() >= deadline):
                    holder = self._holder()
                    os.close(fd)
                    waited = f" after waiting {self.timeout_s:g} s" if self.wait else ""
                    raise LockedError(
                        f"another gravsurvey run holds {self.out_dir} (pid {holder}){waited}; "
                        f"wait for it to finish or use another output directory"
                    ) from None
                time.sleep(0.1)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            try:
                fcntl.flock(self._fd, fcntl.LOCK_UN)
            finally:
                os.close(self._fd)
                self._fd = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __enter__(self) -> "OutputLock":
        return self.acquire()

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.release()
        return False
