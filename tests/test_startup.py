"""Issue 17.4: start-up. The numba kernel cache lives in a user cache folder (never the package
folder), falls back to a private temp folder, and to no cache when nothing is writable (never a
crash); matplotlib is not imported by a run without plots; `run --no-plots` writes no PNG."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

import gravsurvey  # noqa: F401  (chooses numba's cache folder before numba is imported)
from numba import njit

ROOT = Path(__file__).resolve().parents[1]
# a folder nobody (root included) can create entries in
UNWRITABLE = "/proc/gravsurvey-no-such-home"

PROBE = """
import json, os, sys
import gravsurvey
out = {"kind": gravsurvey.NUMBA_CACHE_KIND, "dir": os.environ.get("NUMBA_CACHE_DIR")}
if len(sys.argv) > 1:  # also import kernel modules and run one kernel
    import numpy as np
    from gravsurvey import wavelet
    import gravsurvey.inm.kalman  # many cache=True kernels: decorated at import
    z = np.cumsum(np.random.default_rng(0).standard_normal(64))
    zt, info = wavelet.cosphi_search(z, "db10", "periodization", "soft", steps=2)
    out["n"] = info["n"]
print(json.dumps(out))
"""


def _probe(env_over, *args):
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "TMPDIR", "HOME")}
    env.update(env_over)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    r = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_user_cache_folder_by_home_and_xdg(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    got = _probe({"HOME": str(home), "TMPDIR": str(tmp_path)})
    assert got == {"kind": "user", "dir": str(home / ".cache" / "gravsurvey" / "numba")}
    if sys.platform.startswith("linux"):
        got = _probe({"HOME": str(home), "XDG_CACHE_HOME": str(tmp_path / "xdg")})
        assert got["dir"] == str(tmp_path / "xdg" / "gravsurvey" / "numba")


def test_users_own_numba_cache_dir_is_kept(tmp_path):
    own = tmp_path / "mine"
    got = _probe({"HOME": UNWRITABLE, "NUMBA_CACHE_DIR": str(own)})
    assert got == {"kind": "env", "dir": str(own)}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux-only")
def test_unwritable_home_falls_back_to_a_private_temp_folder(tmp_path):
    got = _probe({"HOME": UNWRITABLE, "TMPDIR": str(tmp_path)}, "run")
    assert got["kind"] == "temp" and got["n"] >= 1
    d = Path(got["dir"])
    assert d.parent == tmp_path and d.name == f"gravsurvey-numba-{os.getuid()}"
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    assert list(d.rglob("*.nbi"))  # the kernels were cached there, not in the package


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux-only")
def test_nothing_writable_means_no_cache_and_no_crash(tmp_path):
    """HOME unwritable and the temp candidate unusable (here: a file in its place): no cache,
    kernels still import, compile and run."""
    (tmp_path / f"gravsurvey-numba-{os.getuid()}").write_text("not a folder")
    got = _probe({"HOME": UNWRITABLE, "TMPDIR": str(tmp_path)}, "run")
    assert got["kind"] == "none" and got["dir"] is None and got["n"] >= 1


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux-only")
def test_temp_folder_writable_by_others_is_not_used(tmp_path):
    """numba's cache files are pickles: a shared folder others can write is never used."""
    shared = tmp_path / f"gravsurvey-numba-{os.getuid()}"
    shared.mkdir()
    shared.chmod(0o777)
    got = _probe({"HOME": UNWRITABLE, "TMPDIR": str(tmp_path)})
    assert got["kind"] == "none"


def test_run_without_plots_does_not_import_matplotlib(tmp_path):
    src = tmp_path / "seed_line"
    shutil.copytree(ROOT / "sample_data" / "seed_line", src)
    out = tmp_path / "out"
    code = (
        "import sys; from gravsurvey.cli import main\n"
        "try:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n"
        "    print('MPL', 'matplotlib' in sys.modules, 'scipy.signal' in sys.modules, e.code)\n"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run(
        [sys.executable, "-c", code, "run", str(src / "survey.yaml"), "-o", str(out), "--no-plots"],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert r.stdout.strip().splitlines()[-1] == "MPL False False 0", (r.stdout, r.stderr)
    assert (out / "profiles.csv").is_file() and not list(out.glob("*.png"))
    summary = json.loads((out / "summary.json").read_text())
    assert not [f for f in summary["output_sha256"] if f.endswith(".png")]


def test_compiling_message_on_a_terminal_only_while_the_cache_is_cold(tmp_path, monkeypatch, capsys):
    from gravsurvey import cli

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cli, "_interactive", lambda: True)
    marker = cli.announce_compilation()
    assert capsys.readouterr().err == "compiling kernels (first run only) ...\n"
    assert marker is not None and marker.parent == tmp_path
    marker.touch()  # what `run` does after a successful run
    assert cli.announce_compilation() is None
    assert capsys.readouterr().err == ""
    # a changed source file (numba recompiles it) makes the cache cold again
    monkeypatch.setattr(cli, "kernel_cache_marker", lambda: tmp_path / "other-stamp")
    assert cli.announce_compilation() is not None
    assert "first run only" in capsys.readouterr().err
    # not on a terminal: never printed
    monkeypatch.setattr(cli, "_interactive", lambda: False)
    cli.announce_compilation()
    assert capsys.readouterr().err == ""


# --- cold start: the second core compiles the kernels of KERNELS (gravsurvey.precompile) -----


@njit  # not cached: this module may import numba before gravsurvey chose the cache folder
def _probe_kernel(x):
    return x.sum() + 1.0


PROBE_KERNELS = ((__name__, "_probe_kernel", "Array(float64, 1, 'C')"),)


def test_kernel_list_names_current_kernels():
    """Every entry of KERNELS is a cached numba kernel of the package, with as many argument
    types as the function has parameters (a stale entry would only cost background CPU)."""
    import importlib
    import inspect

    from numba.core.dispatcher import Dispatcher

    from gravsurvey import precompile

    assert precompile.KERNELS and any(k[1] == precompile.WORKER_FIRST for k in precompile.KERNELS)
    for module, name, sig in precompile.KERNELS:
        disp = getattr(importlib.import_module(module), name)
        assert isinstance(disp, Dispatcher), name
        assert len(precompile.parse_signature(sig)) == len(inspect.signature(disp.py_func).parameters), name


def test_worker_compiles_unclaimed_kernels_into_the_cache(tmp_path):
    """The background process skips what the run claimed, compiles the rest into the cache
    and marks each one done."""
    from gravsurvey import precompile

    cache = tmp_path / "cache"
    claims = tmp_path / "claims"
    claims.mkdir()
    (claims / "0.claim").touch()  # the run took the first kernel
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    r = subprocess.run(
        [sys.executable, "-m", "gravsurvey.precompile", str(claims), "2", "0"],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    assert (claims / "1.done").exists() and not (claims / "0.done").exists()
    second = precompile.KERNELS[1][1]
    assert list(cache.rglob(f"*{second}-*.nbi")) and not list(cache.rglob(f"*{precompile.KERNELS[0][1]}-*.nbi"))


def _no_worker(tmp_path, monkeypatch, script):
    """A Precompiler over PROBE_KERNELS whose background process runs ``script``."""
    from gravsurvey import precompile

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(
        precompile, "_start_worker", lambda folder, kernels: subprocess.Popen([sys.executable, "-c", script])
    )
    return precompile.Precompiler(True, kernels=PROBE_KERNELS)


def test_run_does_not_wait_for_a_background_process_that_died(tmp_path, monkeypatch):
    """The background process claimed the kernel and died: the run compiles it itself."""
    import numpy as np
    from numba.core.dispatcher import Dispatcher

    original = Dispatcher.compile
    with _no_worker(tmp_path, monkeypatch, "pass") as pre:
        assert Dispatcher.compile is not original
        (pre.claims.folder / "0.claim").touch()
        assert _probe_kernel(np.ones(3)) == 4.0
        assert pre.waited == [0]
        folder = pre.claims.folder
    assert Dispatcher.compile is original and not folder.exists()


def test_interrupted_run_stops_the_background_process(tmp_path, monkeypatch):
    """Ctrl-C (or any error) in the run: the background process is stopped, its claim folder
    removed, numba's compile restored."""
    from numba.core.dispatcher import Dispatcher

    original = Dispatcher.compile
    pre = _no_worker(tmp_path, monkeypatch, "import time; time.sleep(600)")
    with pytest.raises(KeyboardInterrupt):
        with pre:
            proc, folder = pre.proc, pre.claims.folder
            raise KeyboardInterrupt
    assert proc.poll() is not None and not folder.exists() and Dispatcher.compile is original


def test_precompiler_off_without_a_writable_cache(tmp_path, monkeypatch):
    from gravsurvey import precompile

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    with precompile.Precompiler(True) as pre:
        assert pre.proc is None
    monkeypatch.setenv("NUMBA_CACHE_DIR", UNWRITABLE)
    with precompile.Precompiler(True) as pre:
        assert pre.proc is None
    with precompile.Precompiler(False) as pre:  # warm cache, or --jobs > 1
        assert pre.proc is None


def test_cold_quickstart_run_shares_the_compilation(tmp_path):
    """The README quickstart with an empty cache: exit 0, the background process compiled
    into the shared cache, nothing left behind; the warm rerun gives the same profiles."""
    src = tmp_path / "data"
    shutil.copytree(ROOT / "sample_data" / "grid_ros2", src)
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    outs = []
    for tag in ("cold", "warm"):
        out = tmp_path / tag
        r = subprocess.run(
            [sys.executable, "-m", "gravsurvey.cli", "run", str(src / "survey.yaml"), "-o", str(out), "--no-plots"],
            env=env,
            capture_output=True,
            text=True,
            timeout=1200,
        )
        assert r.returncode == 0, r.stderr
        assert not list(cache.glob(".gravsurvey-precompile-*"))
        outs.append((out / "profiles.csv").read_bytes())
    from gravsurvey.precompile import KERNELS

    # one compiled signature per listed kernel: the run used the listed one (a second file would
    # mean the run's call-site types moved away from KERNELS, and the background work is lost)
    for module, name, _ in KERNELS:
        files = list(cache.rglob(f"{module.rsplit('.', 1)[1]}.{name}-*.nbc"))
        assert len(files) == 1, (name, files)
    assert outs[0] == outs[1]
