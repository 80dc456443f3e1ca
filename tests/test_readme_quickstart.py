"""The README's quick start, run as written on the shared real file: its import and survey
calibration commands taken from the README's first code block, and the lines the README says
`calibrate` prints compared with what it prints now, so the documented numbers cannot drift
from a run (skipped without ../shared)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from conftest import REAL, real

from adcpdyn.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"
KEYS = ("heading misalignment against the reference (deg):", "moving-bed test:", "noise levels (one standard deviation):")


def _blocks(text: str) -> list[str]:
    return re.findall(r"```\n(.*?)```", text, flags=re.S)


def _commands(block: str, verbs=("import", "calibrate")) -> list[list[str]]:
    out = []
    for line in block.splitlines():
        line = line.split("#", 1)[0].strip()
        if line.startswith("adcpdyn ") and line.split()[1] in verbs:
            out.append([a.replace("$R", str(REAL)) for a in shlex.split(line)[1:]])
    return out


@pytest.mark.slow  # 11 s: `make test-slow`, CI's second step
def test_readme_quick_start_prints_what_the_readme_says(tmp_path, monkeypatch, capsys):
    real("winriver02_transect.PD0")
    text = README.read_text()
    code, printed = _blocks(text)[:2]
    commands = _commands(code)
    assert [c[0] for c in commands] == ["import", "import", "import", "calibrate"]
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        assert main(argv) == 0, argv
    out = capsys.readouterr().out
    for key in KEYS:
        documented = next(line for line in printed.splitlines() if line.startswith(key))
        measured = next(line for line in out.splitlines() if line.startswith(key))
        # the README abridges a line's tail with "..."; everything before it must be what the run prints
        head = documented.split("...")[0].rstrip(" (")
        assert measured.startswith(head), f"README: {documented!r}\nrun:    {measured!r}"
