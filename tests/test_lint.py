"""Issue 17.7: lint (ruff), format (ruff format) and types (mypy) in CI, from the test suite so
that the README's test command runs them. Configuration: [tool.ruff] and [tool.mypy] in
pyproject.toml."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: kept in `ruff format` style: the whole code base (pyproject.toml excludes the generated _unrolled.py)
FORMATTED = ["gravsurvey", "tests", "benchmarks", "examples"]


def _run(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, cwd=cwd, timeout=600)


def test_ruff_lint_passes_on_the_whole_repository():
    r = _run("ruff", "check", "--no-cache", "gravsurvey", "tests", "benchmarks", "examples")
    assert r.returncode == 0, r.stdout + r.stderr


def test_ruff_format_on_formatted_files():
    r = _run("ruff", "format", "--no-cache", "--check", *FORMATTED)
    assert r.returncode == 0, r.stdout + r.stderr


def test_mypy_on_the_public_api(tmp_path):
    r = _run("mypy", "--cache-dir", str(tmp_path / "mypy"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Success" in r.stdout


#: cross-module private uses still to be removed by their owners (issue 17 item 3): the
#: state-space model's use of the Kalman kernels' private matrix helpers (inm/ owned by the
#: horizontal-states work). Nothing else may be added here.
PENDING_PRIVATE = {
    ("gravsurvey/inm/errormodel.py", "gravsurvey.inm.kalman._mm"),
    ("gravsurvey/inm/errormodel.py", "gravsurvey.inm.kalman._transpose"),
}


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _module_of(path: Path, root: Path) -> str:
    rel = path.relative_to(root).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _resolve(path: Path, node, root: Path) -> str:
    """The absolute module name of an ``ImportFrom`` in ``path`` (benchmarks import siblings by name)."""
    if not node.level:
        return node.module or ""
    pkg = _module_of(path, root).split(".")
    if path.name != "__init__.py":
        pkg = pkg[:-1]
    pkg = pkg[: len(pkg) - (node.level - 1)]
    return ".".join(pkg + ([node.module] if node.module else []))


def _is_module(name: str, root: Path) -> bool:
    """Whether ``name`` (e.g. ``gravsurvey.io.writers``, ``run``) is a module of the repository at ``root``."""
    for base in (root, root / "benchmarks"):
        p = base.joinpath(*name.split("."))
        if p.with_suffix(".py").is_file() or (p / "__init__.py").is_file():
            return True
    return False


def private_cross_module_uses(files, root: Path = ROOT) -> list[tuple[str, str, int]]:
    """``(file, module.name, line)`` for every leading-underscore name of another module that
    ``files`` import (``from m import _x``) or use through a module alias (``m._x``)."""
    import ast

    found = []
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        rel = str(path.relative_to(root))
        modules = {}  # local alias -> module of this repository
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                mod = _resolve(path, node, root)
                for a in node.names:
                    if _private(a.name):
                        found.append((rel, f"{mod}.{a.name}", node.lineno))
                    elif _is_module(f"{mod}.{a.name}", root):
                        modules[a.asname or a.name] = f"{mod}.{a.name}"
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if _is_module(a.name, root):
                        modules[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and _private(node.attr)
                and isinstance(node.value, ast.Name)
                and node.value.id in modules
            ):
                found.append((rel, f"{modules[node.value.id]}.{node.attr}", node.lineno))
    return found


def test_no_private_names_imported_across_modules():
    files = (
        sorted((ROOT / "gravsurvey").rglob("*.py"))
        + sorted((ROOT / "benchmarks").glob("*.py"))
        + sorted((ROOT / "examples").glob("*.py"))
    )
    bad = [f"{f}:{ln}: {name}" for f, name, ln in private_cross_module_uses(files) if (f, name) not in PENDING_PRIVATE]
    assert not bad, "private names used across modules (make them public, documented):\n" + "\n".join(bad)


def test_private_import_check_finds_each_form(tmp_path):
    """The checker itself: a from-import, a relative one and an attribute use are all found;
    private aliases of public or outside names are not."""
    for mod in (
        "gravsurvey/__init__.py",
        "gravsurvey/pipeline.py",
        "gravsurvey/geodesy.py",
        "gravsurvey/cache.py",
        "gravsurvey/errors.py",
        "gravsurvey/io/__init__.py",
        "gravsurvey/io/writers.py",
    ):
        (tmp_path / mod).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / mod).write_text("")
    probe = tmp_path / "gravsurvey" / "probe.py"
    probe.write_text(
        "from gravsurvey.pipeline import _rms\nfrom .geodesy import _broadcast\n"
        "import gravsurvey.io.writers as w\nfrom gravsurvey import cache\nw._fmt_float_col(1, 2)\n"
        "cache._sha256('x')\nfrom scipy import fft as _sfft\n"
        "from gravsurvey.errors import check_keys as _ck\nself._x = 1\n"
    )
    names = [n for _, n, _ in private_cross_module_uses([probe], root=tmp_path)]
    assert names == [
        "gravsurvey.pipeline._rms",
        "gravsurvey.geodesy._broadcast",
        "gravsurvey.io.writers._fmt_float_col",
        "gravsurvey.cache._sha256",
    ]
