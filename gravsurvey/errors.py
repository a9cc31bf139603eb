"""gravsurvey's own exception types and the exit codes they map to.

The CLI catches :class:`GravsurveyError` once and turns it into an exit code
and a one-line message (table :data:`EXIT_CODES`, also in the README and
``gravsurvey --help``).
"""

import threading
import os

#: exit code -> meaning; the one table of exit codes (README, ``--help`` and tests use it)
EXIT_OK = 0
EXIT_DATA = 1
EXIT_CONFIG = 2
EXIT_ENVIRONMENT = 3
EXIT_REGRESSION = 4
EXIT_INTERNAL = 70
EXIT_INTERRUPTED = 130
EXIT_CODES = {
    EXIT_OK: "ok",
    EXIT_DATA: "data problem: input missing, damaged or implausible (in at least one flight)",
    EXIT_CONFIG: "usage or configuration error (the message names the option or key path)",
    EXIT_ENVIRONMENT: "environment: permission denied, disk full, unwritable output or cache",
    EXIT_REGRESSION: "regression check failed: `check` found differences beyond tolerance",
    EXIT_INTERNAL: "internal error (a bug in gravsurvey; please report it with the log)",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C / SIGINT); outputs of the run are discarded",
}


class GravsurveyError(Exception):
    """Base class. ``exit_code`` is what the CLI returns."""

    exit_code = 1


class DataError(GravsurveyError):
    """Input data are missing, damaged or implausible (exit code 1)."""

    exit_code = 1


class ConfigError(GravsurveyError):
    """A configuration file or command line is invalid (exit code 2)."""

    exit_code = 2


class EnvironmentFault(GravsurveyError):
    """The machine refused: permission denied, disk full, read-only or missing output (exit 3)."""

    exit_code = 3


class RegressionFailure(GravsurveyError):
    """``gravsurvey check`` found differences beyond tolerance (exit 4)."""

    exit_code = 4


def os_fault(exc: OSError, what: str = "") -> EnvironmentFault:
    """One-line :class:`EnvironmentFault` for an :class:`OSError`, naming its path.

    ``"<path>: cannot <what>: <reason>"``, e.g. ``out/profiles.csv: cannot write: No space
    left on device``; the path is the exception's filename (and filename2, for renames).
    """
    path = exc.filename if exc.filename is not None else "?"
    if exc.filename2 is not None:
        path = f"{path} -> {exc.filename2}"
    reason = exc.strerror or (os.strerror(exc.errno) if exc.errno else type(exc).__name__)
    return EnvironmentFault(
        f"{os.fsdecode(path) if isinstance(path, bytes) else path}: {'cannot ' + what + ': ' if what else ''}{reason}"
    )


class DataWarning(UserWarning):
    """Something in the data was repaired or looks suspicious; processing continues."""


#: Other spellings of units, for :func:`suggest` (letters alone do not tell "dps" is deg/s).
UNIT_SPELLINGS = {
    "dps": "deg/s",
    "deg/sec": "deg/s",
    "degrees/s": "deg/s",
    "dph": "deg/h",
    "deg/hr": "deg/h",
    "rad/sec": "rad/s",
    "rps": "rad/s",
    "m/s2": "m/s^2",
    "m/s/s": "m/s^2",
    "mps2": "m/s^2",
    "m/s**2": "m/s^2",
    "mgal": "mGal",
    "feet": "ft",
    "foot": "ft",
    "meters": "m",
    "metres": "m",
    "eotvos": "E",
}


def suggest(word, choices) -> str:
    """``" (did you mean 'x'?)"`` for the choice nearest to ``word``, or ``""``.

    A choice equal to ``word`` up to case wins, then one that is another spelling of the same
    unit (:data:`UNIT_SPELLINGS`); otherwise the closest by :func:`difflib.get_close_matches`
    with a similarity of at least 0.5.
    """
    import difflib

    names = [str(c) for c in choices]
    same = [c for c in names if c.lower() == str(word).lower()]
    spelled = UNIT_SPELLINGS.get(str(word).strip().lower())
    same = same or ([spelled] if spelled in names else [])
    near = same or difflib.get_close_matches(str(word), names, n=1, cutoff=0.5)
    return f" (did you mean {near[0]!r}?)" if near else ""


def unknown_key_text(key, valid) -> str:
    """``"unknown key (did you mean 'x'?); valid keys here: a, b"``: the one wording of an unknown
    key (the config schema and :func:`check_keys` alike)."""
    valid = [str(v) for v in valid]
    return f"unknown key{suggest(key, valid)}; valid keys here: {', '.join(valid)}"


def check_keys(d, valid, path: str, required=()) -> None:
    """Reject the first key of mapping ``d`` that is not in ``valid``, then any missing ``required``.

    Messages (one format for every configuration section)::

        <path>.<key>: unknown key (did you mean 'x'?); valid keys here: a, b, c
        <path>.<key>: missing required key

    ``path`` is the key path of ``d`` ("" at the top level).
    """
    valid = [str(v) for v in valid]
    for k in d:
        if str(k) not in valid:
            where = f"{path}.{k}" if path else str(k)
            raise ConfigError(f"{where}: {unknown_key_text(k, valid)}")
    for k in required:
        if k not in d:
            where = f"{path}.{k}" if path else str(k)
            raise ConfigError(f"{where}: missing required key")


#: Set by the CLI's SIGINT handler.  A Ctrl-C that lands inside a C callback (numba's LLVM
#: object-cache hook, say) is swallowed there; output transactions check this flag before they
#: publish, so such a run still ends as interrupted with nothing published.
INTERRUPT = threading.Event()

#: Set by :class:`~gravsurvey.io.writers.atomic.OutputTransaction` when it starts publishing
#: (cleared when the next one opens).  The CLI then ignores Ctrl-C: the run's outputs are
#: complete and it ends in the next moment with its normal exit code; exit 130 would say that
#: nothing was published.
PUBLISHED = threading.Event()
