"""Command-line interface: parse, call, report. No science here.

Exit codes: 0 ok, 1 a data problem (in at least one flight), 2 usage or config problem.
Our own errors (:class:`gravsurvey.errors.GravsurveyError`) are caught once, in :func:`main`,
and printed as one line; anything else is a bug and is reported as such, still in one line
plus the log file's location when there is one.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import click

from . import __version__
from .errors import ConfigError, DataWarning, GravsurveyError


def _interactive() -> bool:
    return sys.stderr.isatty()


def _warn_line(message, category, filename, lineno, file=None, line=None):
    # Data warnings are part of the report; keep them to one line each.
    return f"warning: {message}\n"


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gravsurvey")
def cli():
    """gravsurvey: airborne gravimetry by 3D-INM Kalman dynamic inversion.

    \b
    Example:
      gravsurvey simulate configs/seed_smooth.yaml -o survey/
      gravsurvey run survey/survey.yaml
    """


@cli.command()
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "output_dir", type=click.Path(file_okay=False), default=None,
              help="Output directory (overrides output.dir of the config).")
@click.option("-j", "--jobs", type=click.IntRange(1, 256), default=1, show_default=True,
              help="Flights processed in parallel (process pool).")
@click.option("--force", is_flag=True, help="Reprocess flights whose inputs and config are unchanged.")
@click.option("--wait", "wait_s", type=click.FloatRange(0), default=0.0, show_default=True,
              help="Seconds to wait for another run holding the output directory.")
@click.option("-q", "--quiet", is_flag=True, help="No progress or summary output (default when not on a terminal).")
def run(config, output_dir, jobs, force, wait_s, quiet):
    """Process a survey: ingest, 3D-INM Kalman/RTS, wavelet, deliverables.

    \b
    Example:
      gravsurvey run survey.yaml --jobs 4
    Exit code 0 when every flight succeeded, 1 when at least one flight had a
    data problem (failed, or processed from a damaged input salvaged up to the
    damage; the others are still processed and written), 2 for a usage or
    config problem.
    """
    from .pipeline import run_survey

    show = _interactive() and not quiet
    result = run_survey(config, output_dir=output_dir, jobs=jobs, force=force, wait_s=wait_s,
                        progress=show)
    if show or result.data_problem:
        for line in result.report_lines(verbose=show):
            click.echo(line, err=result.data_problem)
    sys.exit(1 if result.data_problem else 0)


@cli.command()
@click.argument("sim_config", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "output_dir", required=True, type=click.Path(file_okay=False),
              help="Directory to write the simulated survey into.")
def simulate(sim_config, output_dir):
    """Simulate a survey with known truth: sensor logs, truth.csv, survey.yaml.

    \b
    Example:
      gravsurvey simulate configs/realistic_survey.yaml -o sim/
      gravsurvey run sim/survey.yaml
    """
    from .simulate.run import simulate_to_dir

    paths = simulate_to_dir(sim_config, output_dir)
    if _interactive():
        for p in paths:
            click.echo(str(p))


@cli.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Machine-readable JSON output.")
@click.option("--config", "config", type=click.Path(dir_okay=False), default=None,
              help="Survey config: each file is read with the topics, JSON fields, CSV "
                   "columns, time format and units of the flight that names it.")
def inspect(files, as_json, config):
    """Describe sensor logs (MCAP or CSV): channels, counts, spans, rates, gaps, unit checks.

    Exit 1 when a file is damaged (what and where is said) or cannot be read.

    \b
    Example:
      gravsurvey inspect flight.mcap
      gravsurvey inspect --config survey.yaml logs/imu.csv
      gravsurvey inspect --json flight.mcap > flight.json
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
@click.option("--tol-mgal", type=click.FloatRange(0), default=0.05, show_default=True,
              help="Largest allowed per-sample change of disturbance_mgal.")
@click.option("--tol-rms-mgal", type=click.FloatRange(0), default=0.02, show_default=True,
              help="Largest allowed change of a line's RMS vs truth / crossover RMS.")
def check(result_dir, reference_dir, tol_mgal, tol_rms_mgal):
    """Compare a run's outputs with a reference run, for CI regression gates.

    \b
    Example:
      gravsurvey check out/ reference_out/ --tol-mgal 0.1
    Exit 0 when within tolerance, 1 with a readable list of differences otherwise.
    """
    from .regression import compare_runs

    diffs = compare_runs(result_dir, reference_dir, tol_mgal=tol_mgal, tol_rms_mgal=tol_rms_mgal)
    if diffs:
        for d in diffs:
            click.echo(d, err=True)
        sys.exit(1)
    if _interactive():
        click.echo("check: outputs agree with the reference within tolerance")


def main(argv=None):
    """Console entry point: runs the click group and maps our errors to exit codes."""
    warnings.formatwarning = _warn_line
    warnings.simplefilter("default", DataWarning)
    try:
        cli.main(args=argv, prog_name="gravsurvey", standalone_mode=False)
    except GravsurveyError as exc:
        click.echo(f"gravsurvey: error: {exc}", err=True)
        sys.exit(exc.exit_code)
    except click.exceptions.Abort:
        click.echo("gravsurvey: aborted", err=True)
        sys.exit(2)
    except click.ClickException as exc:
        click.echo(f"gravsurvey: error: {exc.format_message()}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        click.echo("gravsurvey: interrupted", err=True)
        sys.exit(130)
    except SystemExit:
        raise
    except Exception as exc:  # a bug: still one line, never a traceback on the user's screen
        click.echo(f"gravsurvey: internal error: {type(exc).__name__}: {exc}", err=True)
        sys.exit(3)
    sys.exit(0)


if __name__ == "__main__":  # pragma: no cover
    main()
