"""Command-line interface: parse, call, report. No science here.

Exit codes (:data:`gravsurvey.errors.EXIT_CODES`, also in the README and ``--help``):
0 ok, 1 data problem, 2 usage/config, 3 environment (permissions, disk full, unwritable
output), 4 regression check failed, 70 internal error (a bug), 130 interrupted.
Our own errors (:class:`gravsurvey.errors.GravsurveyError`) are caught once, in :func:`main`,
and printed as one line; so are OS faults (naming the path) and anything else (a bug, still in
one line plus the log file's location when there is one).

Warnings (data repaired or suspicious) always reach people: each is one ``warning: ...`` line
on stderr and in the run's log, and a run with warnings ends with a ``N warnings`` line.
``--quiet`` (and a non-terminal stderr, e.g. cron) drops progress and the summary only.
"""

from __future__ import annotations

import json
import logging
import sys
import warnings
from pathlib import Path

import click

from . import __version__
from .console import exit_interrupted  # a Ctrl-C while this module loads: gravsurvey.console
from .errors import (
    EXIT_CODES,
    EXIT_CONFIG,
    EXIT_INTERNAL,
    EXIT_OK,
    INTERRUPT,
    PUBLISHED,
    ConfigError,
    DataWarning,
    GravsurveyError,
    RegressionFailure,
    os_fault,
)

log = logging.getLogger("gravsurvey")


def _interactive() -> bool:
    return sys.stderr.isatty()


class WarningTally:
    """Counts the warnings shown during one command (``warnings`` module and run notes)."""

    def __init__(self) -> None:
        self.count = 0

    def show(self, message, category=None, filename=None, lineno=None, file=None, line=None):
        """``warnings.showwarning`` replacement: one line on stderr and in the log, counted."""
        self.emit(str(message))

    def emit(self, text: str, *, logged: bool = False) -> None:
        """Print one warning line to stderr (and to the log unless ``logged``), count it."""
        self.count += 1
        click.echo(f"warning: {text}", err=True)
        if not logged:
            log.warning("%s", text)

    def summary_line(self) -> str:
        return f"{self.count} warning{'' if self.count == 1 else 's'}"


TALLY = WarningTally()


def kernel_cache_marker() -> Path | None:
    """Marker file saying the numba cache holds this package's kernels, or None (no cache).

    Named by a stamp of what invalidates numba's cache: the numba and Python versions and the
    (mtime, size) of every source file of the package (numba checks the same per file).
    """
    import hashlib
    import os

    from . import NUMBA_CACHE_KIND

    cache = os.environ.get("NUMBA_CACHE_DIR")
    if NUMBA_CACHE_KIND == "none" or not cache:
        return None
    try:
        from importlib.metadata import version

        numba_version = version("numba")
    except Exception:  # metadata missing (odd installs): the marker just never matches
        numba_version = "?"
    h = hashlib.sha256(f"{numba_version}/{sys.version}".encode())
    pkg = Path(__file__).resolve().parent
    for f in sorted(pkg.rglob("*.py")):
        st = f.stat()
        h.update(f"{f.relative_to(pkg)}:{st.st_mtime_ns}:{st.st_size};".encode())
    return Path(cache) / f".gravsurvey-warm-{h.hexdigest()[:16]}"


def announce_compilation() -> Path | None:
    """On a terminal, say that the first run compiles the kernels; returns the marker to write
    after a successful run (None when warm or no cache)."""
    try:
        marker = kernel_cache_marker()
    except OSError:
        return None
    if marker is not None and marker.exists():
        return None
    if _interactive():
        if marker is None:
            click.echo("compiling kernels (no writable cache folder: on every run) ...", err=True)
        else:
            click.echo("compiling kernels (first run only) ...", err=True)
    return marker


def _exit_code_table() -> str:
    return "\n".join(f"  {code:>3}  {text}" for code, text in EXIT_CODES.items())


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gravsurvey")
def cli():
    """gravsurvey: airborne gravimetry by 3D-INM Kalman dynamic inversion.

    \b
    Example:
      gravsurvey simulate configs/seed_smooth.yaml -o survey/
      gravsurvey run survey/survey.yaml
    """


# the exit-code table in `gravsurvey --help`, from the one table in errors.py
cli.epilog = "\b\nExit codes:\n" + _exit_code_table()


@cli.command()
@click.argument("config", type=click.Path(dir_okay=False))
@click.option(
    "-o",
    "--output",
    "output_dir",
    type=click.Path(file_okay=False),
    default=None,
    help="Output directory (overrides output.dir of the config).",
)
@click.option(
    "-j",
    "--jobs",
    type=click.IntRange(1, 256),
    default=1,
    show_default=True,
    help="Flights processed in parallel (process pool).",
)
@click.option("--force", is_flag=True, help="Reprocess flights whose inputs and config are unchanged.")
@click.option(
    "--wait",
    "wait_s",
    type=click.FloatRange(0),
    default=0.0,
    show_default=True,
    help="Seconds to wait for another run holding the output directory.",
)
@click.option(
    "-q",
    "--quiet",
    is_flag=True,
    help="No progress or summary (default when not on a terminal); warnings and errors are still printed.",
)
@click.option("--no-plots", is_flag=True, help="Write no PNG plots (overrides output.plots).")
def run(config, output_dir, jobs, force, wait_s, quiet, no_plots):
    """Process a survey: ingest, 3D-INM Kalman/RTS, wavelet, deliverables.

    \b
    Example:
      gravsurvey run survey.yaml --jobs 4
    Exit code 0 when every flight succeeded, 1 when at least one flight had a
    data problem (failed, or processed from a damaged input salvaged up to the
    damage; the others are still processed and written), 2 for a usage or
    config problem, 3 when the output cannot be written (permissions, disk
    full), 130 when interrupted (no output of this run is published).
    Warnings go to stderr and the log; a run with warnings ends with "N warnings".
    """
    from .pipeline import run_survey

    show = _interactive() and not quiet
    from .precompile import Precompiler

    marker = announce_compilation()
    # cold cache, one process: the second core compiles the kernels the run needs later
    with Precompiler(marker is not None and jobs == 1):
        result = run_survey(
            config,
            output_dir=output_dir,
            jobs=jobs,
            force=force,
            wait_s=wait_s,
            progress=show,
            plots=False if no_plots else None,
        )
    lost = set(result.data_loss)  # reported below as a data problem, not again as a warning
    for note in result.notes:  # already in the log (pipeline), so only printed and counted
        if note not in lost:
            TALLY.emit(note, logged=True)
    for line in result.report_lines(verbose=False):  # failed flights, salvaged inputs
        click.echo(line, err=True)
    if show:
        for line in result.report_lines(verbose=True, problems=False):
            click.echo(line)
    if show or TALLY.count:
        click.echo(TALLY.summary_line(), err=True)
    if marker is not None and result.processed:
        try:
            marker.touch()
        except OSError:  # the cache folder went away or read-only: only the message repeats
            pass
    sys.exit(1 if result.data_problem else 0)


@cli.command()
@click.argument("sim_config", type=click.Path(dir_okay=False))
@click.option(
    "-o",
    "--output",
    "output_dir",
    required=True,
    type=click.Path(file_okay=False),
    help="Directory to write the simulated survey into.",
)
@click.option(
    "--oracle-config",
    "oracle",
    is_flag=True,
    help="Also write oracle.yaml: the noise model, anomaly prior and exact initial state "
    "matched to the simulated truth (a benchmark reference no user has).",
)
def simulate(sim_config, output_dir, oracle):
    """Simulate a survey with known truth: sensor logs, truth.csv, survey.yaml.

    survey.yaml holds only what a user knows (file layout, rates, triad); the
    estimator's defaults do the rest.

    \b
    Example:
      gravsurvey simulate configs/realistic_survey.yaml -o sim/
      gravsurvey run sim/survey.yaml
    """
    from .simulate.run import simulate_to_dir

    paths = simulate_to_dir(sim_config, output_dir, oracle=oracle)
    if _interactive():
        for p in paths:
            click.echo(str(p))


@cli.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Machine-readable JSON output.")
@click.option(
    "--config",
    "config",
    type=click.Path(dir_okay=False),
    default=None,
    help="Survey config: each file is read with the topics, JSON fields, CSV "
    "columns, time format and units of the flight that names it.",
)
def inspect(files, as_json, config):
    """Describe sensor logs (MCAP or CSV): channels, counts, spans, rates, gaps, unit checks.

    Gravimeter and navigation files (MGD77T, DGS, AT1A, ZLS, BGM-3, NMEA, trajectory text)
    are recognised by their content and described too, with how to process them.
    Exit 1 when a file is damaged (what and where is said) or cannot be read.

    \b
    Example:
      gravsurvey inspect flight.mcap
      gravsurvey inspect --config survey.yaml logs/imu.csv
      gravsurvey inspect --json flight.mcap > flight.json
      gravsurvey inspect DGS_2019.dat nav.gps
    """
    from .io.inspect import format_inspect, inspect_files

    cfg = None
    if config is not None:
        from .config import load_config

        cfg = load_config(config)
    reports = inspect_files(list(files), config=cfg)
    if as_json:
        click.echo(json.dumps(reports, indent=2, default=str))
    else:
        click.echo(format_inspect(reports))
    damaged = [d for r in reports for d in r.get("damage", [])]
    for d in damaged:
        click.echo(f"inspect: {d}", err=True)
    if damaged:
        sys.exit(1)


@cli.command()
@click.argument("config", type=click.Path(dir_okay=False))
def validate(config):
    """Check a processing config without reading any data.

    Runs every check `run` makes before processing (keys, types, ranges, EPSG code,
    post-processor options, truth file header, time windows) and that every input
    file exists. Exit 0 when valid, 2 (one line naming the key path) otherwise.

    \b
    Example:
      gravsurvey validate survey.yaml
    """
    from .config import load_config

    cfg = load_config(config)
    missing = []
    for fl in cfg.flights:
        for p in fl.ingest.input_paths():
            if not Path(p).exists():
                missing.append(f"flights[{fl.index}] ({fl.name}): input file not found: {p}")
            elif not Path(p).is_file():
                missing.append(f"flights[{fl.index}] ({fl.name}): input is not a file: {p}")
    for m in missing:
        click.echo(m, err=True)
    if missing:
        sys.exit(2)
    click.echo(f"{cfg.path}: ok ({len(cfg.flights)} flight(s))")


@cli.command()
@click.argument("path", type=click.Path(dir_okay=False), default="gravsurvey.yaml")
@click.option("--force", is_flag=True, help="Overwrite an existing file.")
def init(path, force):
    """Write a commented example processing config.

    \b
    Example:
      gravsurvey init survey.yaml
    """
    from .templates import EXAMPLE_CONFIG

    p = Path(path)
    if p.exists() and not force:
        raise ConfigError(f"{p}: exists; use --force to overwrite")
    p.write_text(EXAMPLE_CONFIG)
    click.echo(f"wrote {p}")


@cli.command()
@click.argument("result_dir", type=click.Path(file_okay=False))
@click.argument("reference_dir", type=click.Path(file_okay=False))
@click.option(
    "--tol-mgal",
    type=click.FloatRange(0),
    default=0.05,
    show_default=True,
    help="Largest allowed per-sample change of disturbance_mgal.",
)
@click.option(
    "--tol-rms-mgal",
    type=click.FloatRange(0),
    default=0.02,
    show_default=True,
    help="Largest allowed change of a line's RMS vs truth / crossover RMS.",
)
def check(result_dir, reference_dir, tol_mgal, tol_rms_mgal):
    """Compare a run's outputs with a reference run, for CI regression gates.

    \b
    Example:
      gravsurvey check out/ reference_out/ --tol-mgal 0.1
    Exit 0 when within tolerance, 4 with a readable list of differences
    otherwise, 1 when either directory is not a complete gravsurvey output
    (no summary.json, or a file its summary lists is missing or altered).
    """
    from .regression import compare_runs

    diffs = compare_runs(result_dir, reference_dir, tol_mgal=tol_mgal, tol_rms_mgal=tol_rms_mgal)
    if diffs:
        for d in diffs:
            click.echo(d, err=True)
        raise RegressionFailure(f"{result_dir}: {len(diffs)} difference(s) from {reference_dir} beyond tolerance")
    if _interactive():
        click.echo("check: outputs agree with the reference within tolerance")


def _install_sigint_flag():
    """Ctrl-C raises KeyboardInterrupt as usual and also sets :data:`errors.INTERRUPT`."""
    import signal

    INTERRUPT.clear()
    PUBLISHED.clear()
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return  # ignored (a background job) or someone else's handler: leave it

    def on_sigint(signum, frame):
        if INTERRUPT.is_set():
            return  # already on the way out: a second Ctrl-C must not start a second unwinding
        if PUBLISHED.is_set():
            return  # the outputs are published: the run ends in a moment with its own exit code
        INTERRUPT.set()
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_sigint)
    previous = sys.unraisablehook

    def quiet_interrupt(unraisable):
        # the swallowed Ctrl-C would print a traceback; the run reports it once, as exit 130.
        # After a Ctrl-C, an object the interrupt left half-built (llvmlite's PassBuilder when
        # it lands inside numba's compiler) fails in its __del__ as well: a consequence of the
        # interrupt, so it goes to the log, not to the user's screen
        if isinstance(unraisable.exc_value, KeyboardInterrupt) or INTERRUPT.is_set():
            log.debug("after the interrupt, ignored in %r: %r", unraisable.object, unraisable.exc_value)
            return
        previous(unraisable)

    sys.unraisablehook = quiet_interrupt


def main(argv=None):
    """Console entry point: runs the click group and maps every outcome to an exit code."""
    TALLY.count = 0
    warnings.showwarning = TALLY.show
    _install_sigint_flag()
    if not log.handlers:  # outside a run (no log file) logging must not print to stderr itself
        log.addHandler(logging.NullHandler())
    warnings.simplefilter("default", DataWarning)
    try:
        cli.main(args=argv, prog_name="gravsurvey", standalone_mode=False)
    except (KeyboardInterrupt, click.exceptions.Abort):
        # output transactions discard their staging on the way out: nothing is published
        exit_interrupted()
    except Exception as exc:
        if INTERRUPT.is_set():
            # Ctrl-C landed inside library code that turned it into another error (a process
            # pool interrupted while starting raises RuntimeError, a reader a read error): it
            # is still an interrupt
            exit_interrupted()
        _exit_on_error(exc)
    sys.exit(EXIT_OK)


def _exit_on_error(exc: Exception):
    """One line on stderr for ``exc`` and the documented exit code (see :data:`EXIT_CODES`)."""
    if isinstance(exc, GravsurveyError):
        click.echo(f"gravsurvey: error: {exc}", err=True)
        sys.exit(exc.exit_code)
    if isinstance(exc, click.ClickException):
        click.echo(f"gravsurvey: error: {exc.format_message()}", err=True)
        sys.exit(EXIT_CONFIG)
    if isinstance(exc, OSError):  # permissions, disk full, read-only or vanished output
        fault = os_fault(exc)
        click.echo(f"gravsurvey: error: {fault}", err=True)
        sys.exit(fault.exit_code)
    if isinstance(exc, MemoryError):
        click.echo("gravsurvey: error: out of memory (try fewer --jobs or a shorter flight)", err=True)
        sys.exit(os_fault(OSError(12, "Cannot allocate memory")).exit_code)
    # a bug: still one line, never a traceback on the user's screen
    log.error("internal error", exc_info=exc)  # to the run's log file when one is open
    click.echo(f"gravsurvey: internal error: {type(exc).__name__}: {exc}", err=True)
    sys.exit(EXIT_INTERNAL)


if __name__ == "__main__":  # pragma: no cover
    main()
