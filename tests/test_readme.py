"""The README quickstart is what CI runs, and its commands exist."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _quickstart_commands():
    text = (ROOT / "README.md").read_text()
    qs = text.split("## Quickstart", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.*?)\n```", qs, flags=re.S)


def test_quickstart_is_two_commands():
    cmds = _quickstart_commands()
    assert len(cmds) == 2
    assert all("\n" not in c for c in cmds)


def test_ci_runs_the_readme_test_command():
    test_cmd = _quickstart_commands()[1]
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert test_cmd in ci


def test_sample_survey_in_quickstart_exists():
    run_cmd = _quickstart_commands()[0]
    cfg = re.search(r"gravsurvey run (\S+)", run_cmd).group(1)
    assert (ROOT / cfg).is_file()
