"""Issue 17.7: lint (ruff), format (ruff format) and types (mypy) in CI, from the test suite so
that the README's test command runs them. Configuration: [tool.ruff] and [tool.mypy] in
pyproject.toml."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: files kept in `ruff format` style (new and rewritten files; older files are converted when
#: their owners rewrite them, to keep merges of parallel work small)
FORMATTED = [
    "benchmarks/bench_startup.py",
    "gravsurvey/__init__.py",
    "gravsurvey/cache.py",
    "gravsurvey/errors.py",
    "gravsurvey/regression.py",
    "tests/test_cache.py",
    "tests/test_exit_codes.py",
    "tests/test_gyro_turns.py",
    "tests/test_lint.py",
    "tests/test_startup.py",
]


def _run(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, cwd=cwd, timeout=600)


def test_ruff_lint_passes_on_the_whole_repository():
    r = _run("ruff", "check", "--no-cache", "gravsurvey", "tests", "benchmarks")
    assert r.returncode == 0, r.stdout + r.stderr


def test_ruff_format_on_formatted_files():
    r = _run("ruff", "format", "--no-cache", "--check", *FORMATTED)
    assert r.returncode == 0, r.stdout + r.stderr


def test_mypy_on_the_public_api(tmp_path):
    r = _run("mypy", "--cache-dir", str(tmp_path / "mypy"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Success" in r.stdout
