"""Issue 14.5/14.6: documented exit codes, each produced by running the CLI; warnings reach
stderr and the log with a closing count; Ctrl-C and OS faults publish no partial output."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import types
import warnings
from pathlib import Path

import pytest

from gravsurvey import cli
from gravsurvey.errors import EXIT_CODES, DataError

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_data"
EXE = [sys.executable, "-m", "gravsurvey"]


def gs(*args, timeout=600):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run(
        EXE + [str(a) for a in args], capture_output=True, text=True, timeout=timeout, env=env, stdin=subprocess.DEVNULL
    )


def run_in_process(argv, monkeypatch, capsys):
    """main(argv) in this process (for faults injected with monkeypatch): (code, stdout, stderr)."""
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)
    with pytest.raises(SystemExit) as exc:
        cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def _nonblank(text):
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.fixture(scope="module")
def seed_run(tmp_path_factory):
    """One processed copy of the smallest sample survey (seed_line) and its output folder."""
    tmp = tmp_path_factory.mktemp("seed")
    src = tmp / "seed_line"
    shutil.copytree(SAMPLES / "seed_line", src)
    out = tmp / "out"
    r = gs("run", src / "survey.yaml", "-o", out)
    assert r.returncode == 0, r.stderr
    return src, out


def test_exit_code_table_in_help_and_readme():
    r = gs("--help")
    assert r.returncode == 0
    readme = (ROOT / "README.md").read_text()
    for code, text in EXIT_CODES.items():
        assert re.search(rf"^\s+{code}\s+{re.escape(text)}$", r.stdout, re.M), (code, r.stdout)
        assert re.search(rf"^\| {code} \| {re.escape(text)} \|$", readme, re.M), code
    assert sorted(EXIT_CODES) == [0, 1, 2, 3, 4, 70, 130]


def test_exit_2_usage_and_config(tmp_path):
    r = gs("run", "--no-such-option", "x.yaml")
    assert r.returncode == 2 and len(_nonblank(r.stderr)) == 1 and "--no-such-option" in r.stderr
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("survey: {name: x}\nflights: []\n")
    r = gs("run", cfg)
    assert r.returncode == 2 and "flights" in r.stderr and len(_nonblank(r.stderr)) == 1


def test_exit_3_output_below_a_regular_file(seed_run, tmp_path):
    src, _ = seed_run
    blocker = tmp_path / "afile"
    blocker.write_text("not a directory\n")
    r = gs("run", src / "survey.yaml", "-o", blocker / "out")
    assert r.returncode == 3, r.stderr
    lines = _nonblank(r.stderr)
    assert len(lines) == 1 and str(blocker / "out") in lines[0] and "Traceback" not in r.stderr


def test_exit_3_unwritable_output_folder(seed_run, tmp_path):
    """A folder the user may not write: a chmod 555 folder, or (root ignores permissions) a
    folder below /sys, where even root cannot create entries."""
    src, _ = seed_run
    as_root = hasattr(os, "geteuid") and os.geteuid() == 0
    out = Path("/sys/gravsurvey-test-out") if as_root else tmp_path / "ro"
    if not as_root:
        out.mkdir()
        out.chmod(0o555)
    try:
        r = gs("run", src / "survey.yaml", "-o", out)
    finally:
        if not as_root:
            out.chmod(0o755)
    assert r.returncode == 3, r.stderr
    assert str(out) in r.stderr and len(_nonblank(r.stderr)) == 1 and "Traceback" not in r.stderr


@pytest.mark.parametrize("err", [errno.ENOSPC, errno.EACCES, errno.EROFS])
def test_exit_3_disk_full_or_denied_while_writing_outputs(seed_run, tmp_path, monkeypatch, capsys, err):
    """An OS fault while the deliverables are written: one line naming the file, exit 3, and
    the previous outputs untouched (the output transaction is discarded)."""
    from gravsurvey.io import writers

    src, ref_out = seed_run
    out = tmp_path / "out"
    shutil.copytree(ref_out, out)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.suffix != ".log"}

    def full(path, *a, **k):
        raise OSError(err, os.strerror(err), str(path))

    monkeypatch.setattr(writers, "write_geojson", full)
    code, _, stderr = run_in_process(["run", src / "survey.yaml", "-o", out, "--force", "-q"], monkeypatch, capsys)
    assert code == 3, stderr
    lines = _nonblank(stderr)
    assert len(lines) == 1 and "lines.geojson" in lines[0] and os.strerror(err) in lines[0]
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.suffix != ".log"}
    assert after.keys() == before.keys()
    for name in before:
        if name != ".gravsurvey.lock":
            assert after[name] == before[name], name
    assert not [p for p in out.iterdir() if p.name.startswith(".staging")]


def test_exit_70_internal_error_is_one_line(monkeypatch, capsys, tmp_path):
    from gravsurvey import pipeline

    def boom(*a, **k):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(pipeline, "run_survey", boom)
    code, _, stderr = run_in_process(["run", tmp_path / "x.yaml"], monkeypatch, capsys)
    assert code == 70
    assert _nonblank(stderr) == ["gravsurvey: internal error: ZeroDivisionError: float division by zero"]


def test_sigint_while_the_cli_installs_its_handler_is_exit_130(monkeypatch, capsys, tmp_path):
    """A Ctrl-C before cli.main's own handling is in place (it imports ``signal`` to install it;
    seen once at 0.1 s under load): the console entry point ends it with the one line and 130."""
    from gravsurvey import console

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_install_sigint_flag", interrupted)
    with pytest.raises(SystemExit) as exit_:
        console.main(["run", str(tmp_path / "x.yaml")])
    assert exit_.value.code == 130
    assert _nonblank(capsys.readouterr().err) == [console.INTERRUPTED_LINE]


@pytest.mark.parametrize("jobs", [1, 2])
def test_exit_130_on_sigint_publishes_nothing(seed_run, tmp_path, jobs):
    """SIGINT (Ctrl-C) in the middle of a run: exit 130, one line, no output file published and
    no staging folder left (a first run: the output folder holds only the log and lock). With
    --jobs 2 (two flights, a process pool) as well."""
    src, _ = seed_run
    if jobs > 1:
        src = _two_flights(src, tmp_path / "two").parent
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    # a shell's background job ignores SIGINT; the child must have the default disposition
    p = subprocess.Popen(
        EXE + ["run", str(src / "survey.yaml"), "-o", str(out), "--force", "--jobs", str(jobs)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    t0 = time.monotonic()
    log = out / "gravsurvey.log"
    while time.monotonic() - t0 < 120:
        if log.is_file() and "run " in log.read_text():
            break
        time.sleep(0.02)
    if jobs > 1:
        time.sleep(1.0)  # in the middle of the run (spawning: test_sigint_at_any_moment_...)
    p.send_signal(signal.SIGINT)
    _, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, stderr
    assert _nonblank(stderr) == ["gravsurvey: interrupted; no output of this run was published"]
    left = sorted(x.name for x in out.iterdir())
    assert not [n for n in left if not n.startswith(".") and n != "gravsurvey.log"], left
    assert not [n for n in left if n.startswith(".staging")], left


def _two_flights(src: Path, dst: Path) -> Path:
    """A copy of ``src`` (one flight F01) with the same flight again as F02; its config."""
    shutil.copytree(src, dst)
    text = (dst / "survey.yaml").read_text()
    block = text.split("flights:\n", 1)[1].split("\nlines:", 1)[0] + "\n"
    (dst / "survey.yaml").write_text(text.replace(block, block + block.replace("name: F01", "name: F02")))
    return dst / "survey.yaml"


def _children(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return []


# runs gravsurvey as the `gravsurvey` console script does (import the entry point's module,
# call its main), after saying (one byte on stdout) that the interpreter's start-up and the
# package's (`import gravsurvey`: numba cache folder) are over; a Ctrl-C before that prints the
# interpreter's traceback (docs/reliability.md, Known and open). Not through
# `runpy.run_module('gravsurvey')`: its own look-up of `gravsurvey.__main__` is more of that
# start-up, outside any guard of ours (a Ctrl-C 0.1 s after the byte landed there now and then
# under load, an importlib traceback)
_MAIN_AFTER_READY = (
    "import sys, gravsurvey.console as console; sys.stdout.write('R'); sys.stdout.flush(); "
    "sys.argv[0] = 'gravsurvey'; console.main()"
)


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc to see the pool start")
@pytest.mark.parametrize(
    "moment, delay_s, group",
    [
        ("start", 0.1, False),
        ("start", 0.5, False),
        ("start", 1.0, True),
        ("spawn", 0.0, False),
        ("spawn", 0.05, False),
        ("spawn", 0.5, False),
        ("spawn", 0.0, True),
        ("spawn", 0.02, True),
        ("spawn", 0.5, True),
        ("spawn", 1.0, True),
    ],
)
def test_sigint_at_any_moment_of_a_parallel_run(seed_run, tmp_path, moment, delay_s, group):
    """Ctrl-C during `run --jobs 2` at a given moment: ``start`` = after the interpreter has
    started (while gravsurvey loads), ``spawn`` = after the pool's first process appears (the
    workers are being spawned and start up). ``group``: SIGINT to the whole process group, as
    a terminal's Ctrl-C does (workers too), else to the parent alone. Always exit 130, the one
    line, no traceback from any process, nothing published, and within seconds (before: a
    worker's EOFError or KeyboardInterrupt traceback, or a run that never ended)."""
    src, _ = seed_run
    cfg = _two_flights(src, tmp_path / "two")
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    p = subprocess.Popen(
        [sys.executable, "-c", _MAIN_AFTER_READY, "run", str(cfg), "-o", str(out), "--force", "--jobs", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        start_new_session=group,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert p.stdout.read(1) == b"R"
        if moment == "spawn":
            t0 = time.monotonic()
            while not _children(p.pid) and p.poll() is None and time.monotonic() - t0 < 300:
                time.sleep(0.002)
            assert _children(p.pid), "the pool never started"
        time.sleep(delay_s)
        if group:
            os.killpg(p.pid, signal.SIGINT)
        else:
            p.send_signal(signal.SIGINT)
        t_sig = time.monotonic()
        _, stderr = p.communicate(timeout=60)
        took = time.monotonic() - t_sig
    finally:
        if p.poll() is None:  # hung: end it and its workers (they are ours) before failing
            for c in _children(p.pid):
                os.kill(int(c), signal.SIGKILL)
            p.kill()
            p.communicate()
    stderr = stderr.decode()
    assert p.returncode == 130, stderr
    assert _nonblank(stderr) == ["gravsurvey: interrupted; no output of this run was published"], stderr
    assert took < 30, took  # workers are stopped, not waited for (a flight takes longer)
    left = sorted(x.name for x in out.iterdir()) if out.exists() else []
    assert not [n for n in left if not n.startswith(".") and n != "gravsurvey.log"], left
    assert not [n for n in left if n.startswith(".staging")], left


def _duplicate_one_imu_sample(src: Path) -> None:
    imu = src / "F01" / "imu.csv"
    lines = imu.read_text().splitlines()
    data = [i for i, ln in enumerate(lines) if ln[:1].isdigit()]
    lines.insert(data[500] + 1, lines[data[500]])
    imu.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("quiet", [False, True])
def test_warnings_reach_stderr_and_log_with_a_count(tmp_path, quiet):
    src = tmp_path / "mc"
    shutil.copytree(SAMPLES / "markov_csv", src)
    _duplicate_one_imu_sample(src)
    out = tmp_path / "out"
    r = gs("run", src / "survey.yaml", "-o", out, *(["-q"] if quiet else []))
    assert r.returncode == 0, r.stderr
    lines = _nonblank(r.stderr)
    assert lines == ["warning: F01: imu: dropped 1 duplicate samples", "1 warning"], r.stderr
    assert r.stdout == ""
    log = (out / "gravsurvey.log").read_text()
    assert re.search(r" WARNING F01: imu: dropped 1 duplicate samples$", log, re.M)
    # a rerun reuses the cached flight and still reports its warning
    r2 = gs("run", src / "survey.yaml", "-o", out)
    assert _nonblank(r2.stderr)[-1] == "1 warning"


def test_survey_stage_warnings_reach_stderr_and_log(tmp_path):
    """A warning of the survey stage (here a base tie whose window holds none of the flight: the
    flight stays on a relative level) is printed, logged and counted like a flight's own, not
    left in summary.json alone."""
    src = tmp_path / "mc"
    shutil.copytree(SAMPLES / "markov_csv", src)
    cfg = src / "survey.yaml"
    text = cfg.read_text()
    tie = "  tie: {base_gravity_mgal: 980000, before: {start_s: 1.0e+7, stop_s: 1.00001e+7}}\n"
    cfg.write_text(text.replace("  truth: F01/truth.csv\n", "  truth: F01/truth.csv\n" + tie))
    out = tmp_path / "out"
    r = gs("run", cfg, "-o", out)
    assert r.returncode == 0, r.stderr
    lines = _nonblank(r.stderr)
    assert len(lines) == 2 and lines[-1] == "1 warning", r.stderr
    assert lines[0].startswith("warning: F01: base tie not applied, the flight stays on a relative level: ")
    assert "flights[0].tie.before" in lines[0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["notes"] == [lines[0][len("warning: ") :]]
    log = (out / "gravsurvey.log").read_text()
    assert re.search(r" WARNING F01: base tie not applied, the flight stays on a relative level: ", log)


def _stamp_row(path: Path, k: int, stamp: str) -> None:
    """Give the ``k``-th data row of a sample CSV the time stamp ``stamp`` (its first field)."""
    lines = path.read_text().splitlines()
    data = [i for i, ln in enumerate(lines) if ln[:1].isdigit()]
    lines[data[k]] = stamp + "," + lines[data[k]].split(",", 1)[1]
    path.write_text("\n".join(lines) + "\n")


def test_stray_time_stamps_are_dropped_with_a_warning_not_a_memory_bomb(tmp_path):
    """One IMU row and one GNSS row stamped 0 (a logger glitch): before, every grid over the
    channel's time spanned 55 years (13-26 GB; a run was killed at 24 GB). Now each is dropped
    with a warning naming its channel and time, and the flight's result is the intact one's."""
    intact = tmp_path / "intact"
    shutil.copytree(SAMPLES / "markov_csv", intact)
    src = tmp_path / "mc"
    shutil.copytree(SAMPLES / "markov_csv", src)
    _stamp_row(src / "F01" / "imu.csv", 500, "0")
    _stamp_row(src / "F01" / "gnss.csv", 100, "0")
    r0 = gs("run", intact / "survey.yaml", "-o", tmp_path / "out0", "--no-plots")
    r = gs("run", src / "survey.yaml", "-o", tmp_path / "out", "--no-plots")
    assert r0.returncode == 0 and r.returncode == 0, r.stderr
    lines = _nonblank(r.stderr)
    assert lines[-1] == "2 warnings", r.stderr
    for ch in ("imu", "gnss"):
        assert any(
            ln.startswith(f"warning: F01: {ch}: dropped 1 sample(s) with stray time stamps")
            and "1970-01-01T00:00:00Z" in ln
            for ln in lines
        ), r.stderr
    rms0 = json.loads((tmp_path / "out0" / "summary.json").read_text())["rms_vs_truth_mgal"]
    rms = json.loads((tmp_path / "out" / "summary.json").read_text())["rms_vs_truth_mgal"]
    assert rms == pytest.approx(rms0, rel=0.02)


def test_a_rerun_whose_flights_all_fail_leaves_no_earlier_deliverables(tmp_path):
    """A folder holding a good run, rerun after the IMU log was emptied: every flight fails (exit
    1), and summary.json says so instead of the earlier run's profiles passing for this run's
    (fuzzing, 2026-12-04: the earlier profiles.csv and summary.json stayed, failed_flights: [])."""
    src = tmp_path / "mc"
    shutil.copytree(SAMPLES / "markov_csv", src)
    out = tmp_path / "out"
    assert gs("run", src / "survey.yaml", "-o", out, "--no-plots").returncode == 0
    assert (out / "profiles.csv").is_file()
    imu = src / "F01" / "imu.csv"
    imu.write_text("".join(ln for ln in imu.read_text().splitlines(True) if not ln[:1].isdigit()))
    r = gs("run", src / "survey.yaml", "-o", out, "--no-plots")
    assert r.returncode == 1 and "F01" in r.stderr, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["flights"] == {} and len(summary["failed_flights"]) == 1
    assert summary["failed_flights"][0].startswith("F01: ")
    deliverables = [p.name for p in out.iterdir() if not p.name.startswith(".") and p.name != "gravsurvey.log"]
    assert deliverables == ["summary.json"], deliverables


def test_a_truth_of_another_day_is_said_not_scored_as_nothing(tmp_path):
    """A truth file whose times miss the flight (another day's, or in other units): every score
    was null without a word (fuzzing, 2026-12-04); a warning names the key and both spans."""
    src = tmp_path / "mc"
    shutil.copytree(SAMPLES / "markov_csv", src)
    truth = src / "F01" / "truth.csv"
    lines = truth.read_text().splitlines()
    day = 86_400 * 10**9
    for i, ln in enumerate(lines):
        if ln[:1].isdigit():
            t, rest = ln.split(",", 1)
            lines[i] = f"{int(t) + day},{rest}"
    truth.write_text("\n".join(lines) + "\n")
    r = gs("run", src / "survey.yaml", "-o", tmp_path / "out", "--no-plots")
    assert r.returncode == 0, r.stderr
    warned = [ln for ln in _nonblank(r.stderr) if ln.startswith("warning: ")]
    assert len(warned) == 1 and "flights[0].truth covers 0 % of the flight" in warned[0], r.stderr
    assert "(truth 2025-03-11T12:00:00Z.." in warned[0] and "flight 2025-03-10T12:00:00Z.." in warned[0]


def test_a_failed_flight_still_reports_what_was_noticed_before(tmp_path):
    """An IMU log at 10 Hz stamped as 20 Hz (its stamps span half the GNSS's): the flight fails
    later in the navigation, and the warning that names the cause - the IMU covering half the
    other channels' span - is printed with the failure, not lost with the flight (fuzzing,
    2026-12-04: only "the navigation did not settle ... set model.gyro_bias_sigma_degph")."""
    src = tmp_path / "mc"
    shutil.copytree(SAMPLES / "markov_csv", src)
    imu = src / "F01" / "imu.csv"
    lines = imu.read_text().splitlines()
    data = [i for i, ln in enumerate(lines) if ln[:1].isdigit()]
    t0 = int(lines[data[0]].split(",", 1)[0])
    for i in data:
        t, rest = lines[i].split(",", 1)
        lines[i] = f"{t0 + (int(t) - t0) // 2},{rest}"
    imu.write_text("\n".join(lines) + "\n")
    r = gs("run", src / "survey.yaml", "-o", tmp_path / "out", "--no-plots")
    assert r.returncode == 1, r.stderr
    out = _nonblank(r.stderr)
    assert any(ln.startswith("warning: F01: imu covers only 50 % of the gnss time span") for ln in out), r.stderr
    assert any(ln.startswith("gravsurvey: flight failed: F01: ") for ln in out), r.stderr
    assert "Traceback" not in r.stderr


def test_csv_cut_inside_its_last_line_is_processed_and_exit_1(tmp_path):
    """An IMU CSV cut 20 bytes into its last line (a logger stopped mid-write): the flight is
    processed from the complete lines, the damage is one line on stderr naming the file, the
    line and the bytes, the deliverables are written, exit 1 (a damaged input, as for MCAP)."""
    src = tmp_path / "mc"
    shutil.copytree(SAMPLES / "markov_csv", src)
    imu = src / "F01" / "imu.csv"
    raw = imu.read_bytes()
    last_start = raw.rstrip(b"\n").rindex(b"\n") + 1
    imu.write_bytes(raw[: last_start + 20])
    n_line = raw[:last_start].count(b"\n") + 1
    out = tmp_path / "out"
    r = gs("run", src / "survey.yaml", "-o", out, "-q")
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr
    msg = f"F01: {imu}: last line (line {n_line}) cut after 20 bytes, 1 row dropped"
    assert f"gravsurvey: input damaged, processed what was salvaged: {msg}" in _nonblank(r.stderr), r.stderr
    assert (out / "profiles.csv").is_file() and (out / "summary.json").is_file()
    assert msg in json.loads((out / "summary.json").read_text())["flights"]["F01"]["data_loss"]


def test_check_exit_codes(seed_run, tmp_path):
    """check: 0 agree, 4 differ (a file of the reference missing from the result), 1 when the
    reference is not a complete output (no summary.json, or a listed file missing)."""
    _, out = seed_run
    assert gs("check", out, out).returncode == 0
    ref = tmp_path / "ref"
    shutil.copytree(out, ref)
    res = tmp_path / "res"
    shutil.copytree(out, res)
    summary = json.loads((res / "summary.json").read_text())
    del summary["output_sha256"]["profiles.xyz"]
    (res / "profiles.xyz").unlink()
    (res / "summary.json").write_text(json.dumps(summary))
    r = gs("check", res, ref)
    assert r.returncode == 4, r.stderr
    assert "profiles.xyz: in the reference, missing from the result" in r.stderr
    assert _nonblank(r.stderr)[-1].startswith("gravsurvey: error: ")
    (ref / "lines.geojson").unlink()
    r = gs("check", out, ref)
    assert r.returncode == 1 and "lines.geojson: missing" in r.stderr and "reference" in r.stderr
    (ref / "summary.json").unlink()
    r = gs("check", out, ref)
    assert r.returncode == 1 and "summary.json: missing" in r.stderr
    assert len(_nonblank(r.stderr)) == 1


def test_teardown_errors_after_sigint_stay_off_the_screen(monkeypatch, capsys):
    """A Ctrl-C inside numba's compiler leaves an llvmlite object half-built whose ``__del__``
    then fails (AttributeError): after the interrupt that is logged, not printed. Before one,
    such an error still reaches the previous hook."""
    from gravsurvey.errors import INTERRUPT

    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(u.exc_value))
    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        cli._install_sigint_flag()
        hook = sys.unraisablehook
        unraisable = types.SimpleNamespace(
            exc_value=AttributeError("'PassBuilder' object has no attribute '_as_parameter_'"), object=None
        )
        hook(unraisable)
        assert seen == [unraisable.exc_value]
        INTERRUPT.set()
        hook(unraisable)
        hook(types.SimpleNamespace(exc_value=KeyboardInterrupt(), object=None))
        assert seen == [unraisable.exc_value]
    finally:
        signal.signal(signal.SIGINT, previous)
        INTERRUPT.clear()
    assert capsys.readouterr().err == ""


def test_flight_error_after_a_swallowed_sigint_is_an_interrupt(seed_run, monkeypatch, capsys, tmp_path):
    """A Ctrl-C swallowed inside numba's compiler makes the next call fail ("no compiled object
    yet"): with the interrupt flag set that is exit 130 and nothing published, not a failed
    flight with exit 1."""
    from gravsurvey import pipeline
    from gravsurvey.errors import INTERRUPT

    src, _ = seed_run

    def half_compiled(*a, **k):
        INTERRUPT.set()
        raise RuntimeError("no compiled object yet for <Library 'mechanize_kernel'>")

    monkeypatch.setattr(pipeline, "process_flight", half_compiled)
    out = tmp_path / "out"
    try:
        code, _, stderr = run_in_process(["run", src / "survey.yaml", "-o", out, "--force", "-q"], monkeypatch, capsys)
    finally:
        INTERRUPT.clear()
    assert code == 130, stderr
    assert _nonblank(stderr) == ["gravsurvey: interrupted; no output of this run was published"]
    assert not [p.name for p in out.iterdir() if not p.name.startswith(".") and p.name != "gravsurvey.log"]


@pytest.mark.parametrize(
    "error",
    [RuntimeError("pool interrupted while starting"), OSError(5, "Input/output error"), DataError("x.csv: truncated")],
)
def test_any_error_after_a_swallowed_sigint_is_an_interrupt(monkeypatch, capsys, tmp_path, error):
    """Whatever error a swallowed Ctrl-C turns into further up (a bug's, an I/O or a data
    error), the run reports the interrupt: exit 130, one line."""
    from gravsurvey import pipeline
    from gravsurvey.errors import INTERRUPT

    def interrupted(*a, **k):
        INTERRUPT.set()
        raise error

    monkeypatch.setattr(pipeline, "run_survey", interrupted)
    try:
        code, _, stderr = run_in_process(["run", tmp_path / "x.yaml"], monkeypatch, capsys)
    finally:
        INTERRUPT.clear()
    assert code == 130, stderr
    assert _nonblank(stderr) == ["gravsurvey: interrupted; no output of this run was published"]


def test_interrupt_through_exec_still_exits_130(tmp_path):
    """A Ctrl-C that passes through an ``exec`` of a string (dataclasses, numba and pydantic
    build code so) marks CPython as interrupted; under ``python -m`` the process would then die
    of SIGINT (returncode -2) although the run handled it. exit_interrupted clears the mark."""
    (tmp_path / "interrupted_in_exec.py").write_text(
        "from gravsurvey.console import exit_interrupted\n"
        "try:\n"
        "    exec('raise KeyboardInterrupt')\n"
        "except KeyboardInterrupt:\n"
        "    exit_interrupted()\n"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run(
        [sys.executable, "-m", "interrupted_in_exec"], cwd=tmp_path, capture_output=True, text=True, env=env
    )
    assert r.returncode == 130, (r.returncode, r.stderr)
    assert _nonblank(r.stderr) == ["gravsurvey: interrupted; no output of this run was published"]


def test_ctrl_c_once_the_outputs_are_published_is_ignored(seed_run, monkeypatch, capsys, tmp_path):
    """A Ctrl-C during the publication of the outputs: the commit finishes and the run ends with
    its own exit code, 0, every output complete (before: exit 130 and "no output of this run was
    published" although it had been, or new and previous files mixed)."""
    from gravsurvey.io.writers import atomic

    src, ref = seed_run
    real_replace = os.replace
    sent = []

    def replace_then_interrupt(src_path, dst):
        if ".staging-" in str(src_path) and ".staging-" not in str(dst) and not sent:  # the commit
            sent.append(dst)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
        real_replace(src_path, dst)

    monkeypatch.setattr(atomic.os, "replace", replace_then_interrupt)
    out = tmp_path / "out"
    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        code, _, stderr = run_in_process(["run", src / "survey.yaml", "-o", out, "--force", "-q"], monkeypatch, capsys)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert sent, "the publication never started"
    assert code == 0, stderr
    assert "interrupted" not in stderr
    published = sorted(p.name for p in out.iterdir() if not p.name.startswith(".") and p.name != "gravsurvey.log")
    assert published == sorted(
        p.name for p in ref.iterdir() if not p.name.startswith(".") and p.name != "gravsurvey.log"
    )
    summary = json.loads((out / "summary.json").read_text())
    for name, sha in summary["output_sha256"].items():
        assert hashlib.sha256((out / name).read_bytes()).hexdigest() == sha, name


@pytest.mark.parametrize("after_s", [0.0, 0.05, 0.15])
def test_ctrl_c_after_publishing_leaves_a_finished_run(seed_run, tmp_path, after_s):
    """SIGINT (a real signal) once summary.json, the last output, has appeared: the run is
    finished and ends with exit 0 and its outputs complete. Before, the interpreter's shutdown
    (0.3-0.4 s with numba loaded) restored the default action and the signal killed the process
    (returncode -2, a shell's 130) in 20 of 40 runs signalled in the last 0.8 s."""
    src, _ = seed_run
    out = tmp_path / "out"
    p = subprocess.Popen(
        EXE + ["run", str(src / "survey.yaml"), "-o", str(out), "--force", "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    t0 = time.monotonic()
    while not (out / "summary.json").exists() and p.poll() is None and time.monotonic() - t0 < 120:
        time.sleep(0.002)
    time.sleep(after_s)
    p.send_signal(signal.SIGINT)
    _, stderr = p.communicate(timeout=120)
    assert p.returncode == 0, (p.returncode, stderr)
    summary = json.loads((out / "summary.json").read_text())
    for name, sha in summary["output_sha256"].items():
        assert hashlib.sha256((out / name).read_bytes()).hexdigest() == sha, name
