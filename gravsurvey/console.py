"""The ``gravsurvey`` console script: the command line's entry point.

It only imports :mod:`gravsurvey.cli` and calls :func:`gravsurvey.cli.main`; a Ctrl-C while that
import runs (click, the package's modules: a few tenths of a second on a loaded machine, before
:func:`~gravsurvey.cli.main` installs its own handling) ends the same way as one during a run:
exit 130 and one line, never a traceback.
"""

from __future__ import annotations

import sys

from .errors import EXIT_INTERRUPTED

#: the line an interrupted run ends with (the same text as gravsurvey.cli.INTERRUPTED_LINE)
INTERRUPTED_LINE = "gravsurvey: interrupted; no output of this run was published"


def main(argv=None):
    """Import the CLI and run it; Ctrl-C during the import: exit 130 with one line."""
    try:
        from .cli import main as cli_main
    except KeyboardInterrupt:
        sys.stderr.write(INTERRUPTED_LINE + "\n")
        sys.exit(EXIT_INTERRUPTED)
    cli_main(argv)
