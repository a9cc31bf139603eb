"""The ``gravsurvey`` console script: the command line's entry point.

It only imports :mod:`gravsurvey.cli` and calls :func:`gravsurvey.cli.main`; a Ctrl-C while that
import runs (click, the package's modules: a few tenths of a second on a loaded machine, before
:func:`~gravsurvey.cli.main` installs its own handling) ends the same way as one during a run:
exit 130 and one line, never a traceback.
"""

from __future__ import annotations

import sys

from .errors import EXIT_INTERRUPTED, PUBLISHED

#: the line an interrupted run ends with
INTERRUPTED_LINE = "gravsurvey: interrupted; no output of this run was published"


def exit_interrupted():
    """Write :data:`INTERRUPTED_LINE` to stderr and exit with :data:`EXIT_INTERRUPTED` (130).

    A ``KeyboardInterrupt`` that passed through an ``exec`` of a string (dataclasses, numba and
    pydantic build code that way, so a Ctrl-C often lands there) leaves CPython (3.10-3.13)
    marked as interrupted: under ``python -m gravsurvey`` the process would then end killed by
    SIGINT instead of with exit 130. Any ``exec`` of a string that completes clears that mark.
    """
    sys.stderr.write(INTERRUPTED_LINE + "\n")
    sys.stderr.flush()
    exec("pass")
    sys.exit(EXIT_INTERRUPTED)


def main(argv=None):
    """Import the CLI and run it; Ctrl-C during the import: exit 130 with one line."""
    try:
        from .cli import main as cli_main
    except KeyboardInterrupt:
        exit_interrupted()
    try:
        cli_main(argv)
    except KeyboardInterrupt:
        # before cli.main has its own handling in place: its set-up imports ``signal`` to
        # install it (tens of ms under load; a Ctrl-C at 0.1 s landed there in a test run)
        exit_interrupted()
    finally:
        if PUBLISHED.is_set():
            # the outputs are published and the exit code decided; the interpreter's shutdown
            # (0.3-0.4 s with numba loaded) restores the default SIGINT action, so a Ctrl-C
            # then killed a finished run (returncode -2, shell 130): from here on it is ignored
            import signal

            signal.signal(signal.SIGINT, signal.SIG_IGN)
