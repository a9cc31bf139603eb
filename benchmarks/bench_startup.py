#!/usr/bin/env python
"""Start-up and warm speed (issue 17.4): cold first run, warm runs, as ratios to the goals.

Usage::

    python benchmarks/bench_startup.py [--quick] [--base OTHER_CHECKOUT] [--cold-only]

``--base``: the cold/warm pairs of another checkout (e.g. a worktree at the commit before a
change, run with its own ``.venv`` when it has one) interleaved with this one's;
``--cold-only``: without the flight-hour rows.  Also prints an idle-machine estimate of the cold
run's wall time from CPU times (:func:`idle_estimate`).

Prints a Markdown table; ``run(quick) -> list[dict]`` returns its rows.  Timings are reported,
never asserted.  Goals (issue 17.4, on a 2-core machine):

* cold: the README quickstart's run of ``sample_data/grid_ros2`` in a clean copy, with an
  empty numba cache (``NUMBA_CACHE_DIR`` set to a fresh temporary folder), as a whole process
  (``python -m gravsurvey.cli run``): <= 20 s wall;
* warm, 1 flight-hour of 100 Hz IMU (simulated, MCAP ROS 2, the default configuration the
  simulator writes): <= 1 s for ``pipeline.run_survey`` in a process that has already run once
  (in-process), and <= 2 s as a whole ``gravsurvey run`` process.

Each cold run is paired with a warm run of the same sample right after it (same cache folder,
now filled): the pair's ratio is the price of compilation.  Wall and CPU time (user + system
of the child processes) are both reported: on a shared machine the wall time of a
single-threaded compilation is inflated by the other load, its CPU time much less.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
for _p in (str(REPO), str(REPO / "benchmarks")):
    if _p not in sys.path:
        sys.path.insert(0, _p)

GOAL_COLD_S = 20.0
GOAL_WARM_IN_PROCESS_S = 1.0
GOAL_WARM_PROCESS_S = 2.0

IN_PROCESS = """
import json, sys, time
from gravsurvey.pipeline import run_survey
cfg, out, reps = sys.argv[1], sys.argv[2], int(sys.argv[3])
run_survey(cfg, output_dir=out + "/first", force=True)  # loads the cached kernels
times, cpus = [], []
for i in range(reps):
    t, c = time.perf_counter(), time.process_time()
    res = run_survey(cfg, output_dir=f"{out}/{i}", force=True)
    times.append(time.perf_counter() - t)
    cpus.append(time.process_time() - c)
    assert not res.failed, res.failed
print(json.dumps([times, cpus]))
"""


def _env(cache: Path, repo: Path = REPO) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(repo))
    env.pop("PYTHONSTARTUP", None)
    return env


def _timed(cmd, env, cwd) -> tuple[float, float]:
    """Wall and CPU (children's user + system) seconds of one process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} exited {p.returncode}: {p.stderr.strip()[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _python(repo: Path = REPO) -> str:
    """The interpreter for ``repo``: its own ``.venv`` when it has one (an editable install
    of another checkout in this venv would shadow ``PYTHONPATH``), else this one."""
    own = repo / ".venv" / "bin" / "python"
    return str(own) if repo != REPO and own.exists() else sys.executable


def _run_cmd(cfg: Path, out: Path, repo: Path = REPO) -> list[str]:
    return [_python(repo), "-m", "gravsurvey.cli", "run", str(cfg), "-o", str(out), "--force"]


def _stats(v) -> dict:
    v = np.asarray(v, float)
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max()), "n": int(v.size)}


#: ``gravsurvey run`` as ``python -m gravsurvey.cli run`` does it, writing the CPU seconds of
#: the run's own process (without the processes it started) to the file ``argv[1]``
OWN_CPU = """
import json, resource, sys
from gravsurvey.cli import main
try:
    main(sys.argv[2:])
finally:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    with open(sys.argv[1], "w") as fh:
        fh.write(json.dumps(ru.ru_utime + ru.ru_stime))
"""


def _cold_warm_pair(work: Path, tag: str, repo: Path) -> tuple[float, float, float, float, float]:
    """One cold run in a fresh copy with an empty cache, then a warm run of it: wall and CPU
    of each, and the CPU of the cold run's own process (without a background compiler)."""
    d = work / tag
    shutil.copytree(REPO / "sample_data" / "grid_ros2", d / "data")
    cache = d / "numba-cache"
    cache.mkdir()
    env = _env(cache, repo)
    own = d / "own_cpu.json"
    cfg = d / "data" / "survey.yaml"
    cmd = [_python(repo), "-c", OWN_CPU, str(own), "run", str(cfg), "-o", str(d / "out_cold"), "--force"]
    cw, cc = _timed(cmd, env, d)
    ww, wc = _timed(_run_cmd(cfg, d / "out_warm", repo), env, d)
    return cw, cc, ww, wc, float(json.loads(own.read_text()))


def cold_and_warm_sample(work: Path, pairs: int, base: Path | None = None) -> list[dict]:
    """``pairs`` x (cold run in a fresh copy with an empty cache, then a warm run of it).

    With ``base`` (another checkout, e.g. the commit before a change), each pair of this
    checkout is interleaved with one of ``base`` (same load on a shared machine), and the
    rows of both are returned, ``base`` first.
    """
    sides = [("this", REPO)] if base is None else [("base", base), ("this", REPO)]
    got: dict = {name: ([], [], [], [], []) for name, _ in sides}
    for i in range(pairs):
        for name, repo in sides if i % 2 == 0 else sides[::-1]:
            for lst, x in zip(got[name], _cold_warm_pair(work, f"{name}{i}", repo)):
                lst.append(x)
    rows = []
    for name, _ in sides:
        rows += _cold_warm_rows(*got[name], "" if base is None else f" [{name}]")
    return rows


def _cold_warm_rows(cold_w, cold_c, warm_w, warm_c, own_c, label="") -> list[dict]:
    cw, cc, ww, wc = _stats(cold_w), _stats(cold_c), _stats(warm_w), _stats(warm_c)
    return [
        {
            "case": "sample survey, cold (empty numba cache), whole process" + label,
            "wall": cw,
            "cpu": cc,
            "goal_s": GOAL_COLD_S,
            "ratio_to_goal": cw["median"] / GOAL_COLD_S,
            "cpu_ratio_to_goal": cc["median"] / GOAL_COLD_S,
            "cold_over_warm": float(np.median(np.array(cold_w) / np.array(warm_w))),
        },
        {
            "case": "sample survey, cold, CPU of the run's own process (no background compiler)" + label,
            "wall": None,
            "cpu": _stats(own_c),
            "goal_s": None,
        },
        {"case": "sample survey, warm, whole process" + label, "wall": ww, "cpu": wc, "goal_s": None},
    ]


def warm_flight_hour(work: Path, reps: int) -> list[dict]:
    """1 flight-hour at 100 Hz, warm: whole processes and in-process repetitions."""
    from run import simulate, speed_sim

    cfg = simulate(speed_sim(3600.0, 100.0), work, "hour100")
    cache = work / "numba-cache-hour"
    cache.mkdir()
    env = _env(cache)
    _timed(_run_cmd(cfg, work / "hour_first"), env, work)  # compiles: not timed
    proc_w, proc_c = [], []
    for i in range(reps):
        w, c = _timed(_run_cmd(cfg, work / f"hour_proc{i}"), env, work)
        proc_w.append(w)
        proc_c.append(c)
    p = subprocess.run(
        [sys.executable, "-c", IN_PROCESS, str(cfg), str(work / "hour_inproc"), str(reps)],
        env=env,
        cwd=work,
        capture_output=True,
        text=True,
        timeout=3600,
    )
    if p.returncode != 0:
        raise RuntimeError(f"in-process timing exited {p.returncode}: {p.stderr.strip()[-2000:]}")
    times, cpus = json.loads(p.stdout.strip().splitlines()[-1])
    inproc = _stats(times)
    # the fixed price of a process: interpreter, imports (no kernel runs)
    imp_w = [
        _timed([sys.executable, "-c", "import gravsurvey.cli, gravsurvey.pipeline"], env, work)[0] for _ in range(reps)
    ]
    pw = _stats(proc_w)
    return [
        {
            "case": "1 flight-hour, 100 Hz, warm, in-process (run_survey)",
            "wall": inproc,
            "cpu": _stats(cpus),
            "goal_s": GOAL_WARM_IN_PROCESS_S,
            "ratio_to_goal": inproc["median"] / GOAL_WARM_IN_PROCESS_S,
        },
        {
            "case": "1 flight-hour, 100 Hz, warm, whole process (gravsurvey run)",
            "wall": pw,
            "cpu": _stats(proc_c),
            "goal_s": GOAL_WARM_PROCESS_S,
            "ratio_to_goal": pw["median"] / GOAL_WARM_PROCESS_S,
        },
        {
            "case": "imports only (gravsurvey.cli, gravsurvey.pipeline), whole process",
            "wall": _stats(imp_w),
            "cpu": None,
            "goal_s": None,
        },
    ]


#: one cold run of the sample in this process with the background compiler, timed by CPU
IDLE_ESTIMATE = """
import json, os, sys, time
cache, cfg, out = sys.argv[1:4]
os.environ["NUMBA_CACHE_DIR"] = cache
from gravsurvey import precompile
from gravsurvey.pipeline import run_survey

waits = []
wait = precompile.Precompiler._wait

def timed_wait(self, i):
    c = time.process_time()
    wait(self, i)
    waits.append((i, c, time.process_time()))

precompile.Precompiler._wait = timed_wait
c_enter = time.process_time()
with precompile.Precompiler(True) as pre:
    run_survey(cfg, output_dir=out, force=True)
    done = {int(p.stem): float(p.read_text()) for p in pre.claims.folder.glob("*.done")}
own = time.process_time()
idle = 0.0
for i, c0, c1 in waits:
    if i in done:
        idle += max(0.0, c_enter + done[i] - (c1 + idle))
print(json.dumps({"own_cpu": own, "idle_wait": idle, "estimate": own + idle, "background_cpu": max(done.values(), default=0.0)}))
"""


def idle_estimate(work: Path, reps: int) -> list[dict]:
    """Wall time of a cold run on an idle 2-core machine, estimated from CPU times (a shared
    machine inflates wall times, and the background compiler gets no core of its own there).

    Model: each process runs at 1 CPU second per second; the run's clock is its CPU time, and a
    wait for a kernel of the background process ends no earlier than that process's CPU time at
    the kernel's ``.done`` file (which records it), counted from the run's CPU time when it
    started the background process.  I/O waits are ignored (the sample is read from the page
    cache).  For a one-process run the model gives its CPU time.
    """
    got = []
    for i in range(reps):
        d = work / f"estimate{i}"
        (d / "cache").mkdir(parents=True)
        p = subprocess.run(
            [
                sys.executable,
                "-c",
                IDLE_ESTIMATE,
                str(d / "cache"),
                str(REPO / "sample_data/grid_ros2/survey.yaml"),
                str(d / "out"),
            ],
            env=_env(d / "cache"),
            capture_output=True,
            text=True,
            timeout=3600,
        )
        if p.returncode != 0:
            raise RuntimeError(f"idle estimate exited {p.returncode}: {p.stderr.strip()[-2000:]}")
        got.append(json.loads(p.stdout.strip().splitlines()[-1]))
    est = _stats([g["estimate"] for g in got])
    return [
        {
            "case": "sample survey, cold, idle 2-core estimate from CPU (in-process run_survey)",
            "wall": est,
            "cpu": _stats([g["own_cpu"] for g in got]),
            "goal_s": GOAL_COLD_S,
            "ratio_to_goal": est["median"] / GOAL_COLD_S,
        }
    ]


def run(quick: bool = False, base: Path | None = None, cold_only: bool = False) -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="gravsurvey-startup-") as tmp:
        work = Path(tmp)
        rows = cold_and_warm_sample(work, 1 if quick else 3, base)
        rows += idle_estimate(work, 1 if quick else 3)
        if not cold_only:
            rows += warm_flight_hour(work, 3 if quick else 7)
    return rows


def _fmt(s) -> str:
    if s is None:
        return "-"
    return f"{s['median']:.2f} [{s['min']:.2f}, {s['max']:.2f}] (n={s['n']})"


def main(argv=None):
    argv = list(argv if argv is not None else sys.argv[1:])
    base = Path(argv[argv.index("--base") + 1]).resolve() if "--base" in argv else None
    rows = run("--quick" in argv, base, "--cold-only" in argv)
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print("| case | wall s, median [range] | CPU s, median [range] | goal | median / goal |")
    print("|---|---|---|---|---|")
    for r in rows:
        goal = "-" if r["goal_s"] is None else f"<= {r['goal_s']:g} s wall"
        ratio = "-" if r["goal_s"] is None else f"{r['ratio_to_goal']:.2f}"
        if "cpu_ratio_to_goal" in r:
            ratio += f" (CPU: {r['cpu_ratio_to_goal']:.2f}; cold / warm {r['cold_over_warm']:.1f})"
        print(f"| {r['case']} | {_fmt(r['wall'])} | {_fmt(r['cpu'])} | {goal} | {ratio} |")


if __name__ == "__main__":
    main()
