"""Issue 14 item 11: a clone of the repository passes its tests alone. No test names a path
outside the repository (the outside data the tests need is copied into tests/data), and every
folder of tests/data says where its files come from and under which licence."""

from __future__ import annotations

import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent
# ../shared, /work/..., a home folder: places that exist on the machine the suite was written
# on; and Path(__file__).parents[2] or higher, which from tests/ leaves the repository (the form
# the tests used before: parents[2] / the outside folder / external)
#: the folder's name, spelled so that this file itself does not read as one that uses it
SH = "sha" + "red"
OUTSIDE = re.compile(r"""["'](?:\.\./+)+shared|["']/work/|["']/home/|["']~/|parents\[[2-9]\]|/\s*["']shared["']""")


def test_no_test_reads_outside_the_repository():
    hits = []
    for f in sorted(TESTS.rglob("*.py")):
        if f == Path(__file__).resolve():
            continue  # its own pattern and examples
        for i, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            if OUTSIDE.search(line):
                hits.append(f"{f.relative_to(TESTS)}:{i}: {line.strip()}")
    assert not hits, "\n".join(hits)


def test_every_data_folder_names_its_origin_and_licence():
    for d in sorted(p for p in (TESTS / "data").iterdir() if p.is_dir()):
        docs = [p for p in d.iterdir() if p.is_file() and re.match(r"(?i)(readme|notes?|licen[cs]e)", p.name)]
        assert docs, f"tests/data/{d.name}: no README/NOTES/LICENSE file"
        text = " ".join(p.read_text(encoding="utf-8", errors="replace") for p in docs)
        assert re.search(r"(?i)licen[cs]e|public domain|MIT|BSD|Apache|MPL|CC[- ]", text), d.name


def test_the_pattern_catches_what_it_is_for():
    q = '"'
    for bad in (
        f"Path({q}../{SH}/external/x{q})",
        f"open({q}/work/{SH}/a.csv{q})",
        f"Path({q}../../{SH}{q})",
        f"Path(__file__).resolve().parents[2] / {q}{SH}{q}",
    ):
        assert OUTSIDE.search(bad), bad
    assert not OUTSIDE.search('Path(__file__).parent / "data" / "real-imu"')
