"""docs/status.md's table of targets: every target the committed benchmark results record
(``benchmarks/results/*.json``, each written by the command named beside it), its measured value and
whether it is met, and the diagnosis self-tests' scores: ``python -m adcpdyn.benchmarks.status``
prints it (markdown) and ``... --write docs/status.md`` puts it between the page's markers, so the
page's figures are those of the committed runs, never typed
(``tests/test_docs_numbers.py`` checks the page against it). A quick run's file is listed only where
no full run of its suite is committed."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"

# result file -> (issue, the command that writes it), in the page's order
SUITES = {
    "diagnosis_random_walk.json": ("23", "ADCPDYN_BENCH_NAVIGATION=random_walk adcpdyn bench diagnosis"),
    "diagnosis-survey.json": ("23", "adcpdyn bench diagnosis-survey"),
    "navigation.json": ("23", "adcpdyn bench navigation"),
    "scale.json": ("25", "adcpdyn bench scale"),
    "surveyday.json": ("25", "adcpdyn bench surveyday"),
    "correction.json": ("25", "adcpdyn bench correction"),
    "solvers.json": ("25", "adcpdyn bench solvers"),
    "compliance.json": ("26", "adcpdyn bench compliance"),
    "calibration.json": ("3, 24", "adcpdyn bench calibration"),
    "formulations.json": ("3", "adcpdyn bench formulations"),
    "survey.json": ("16, 24", "adcpdyn bench survey"),
}
# the diagnosis self-tests on simulated cases (`adcpdyn diagnose --selftest ...`): their summaries
SELFTESTS = {
    "diagnose_selftest_calibrated.json": ("19, 23", "adcpdyn diagnose --selftest 30 --seed 2 --selftest-calibrated"),
    "diagnose_selftest.json": ("5, 19", "adcpdyn diagnose --selftest 40 --seed 1"),
}


def _value(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "not run"
    return f"{v:.4g}"


def _committed(name: str, folder: Path) -> tuple[Path | None, bool]:
    """(the file of ``name``'s suite, whether it is a quick run): the full run's, else the quick one's."""
    full, quick = folder / name, folder / name.replace(".json", "_quick.json")
    if full.is_file():
        return full, False
    return (quick, True) if quick.is_file() else (None, False)


def markdown_table(folder: Path = RESULTS) -> str:
    """Per committed result, its issue(s) and command, then its targets: target, measured value, met."""
    sections = []

    def section(issue: str, name: str, command: str, rows: list) -> None:
        lines = [f"**Issue{'s' if ',' in issue else ''} {issue}** — `benchmarks/results/{name}`, written by `{command}`:", "",
                 "| target | measured | met |", "|---|---:|:---:|"]
        lines += [f"| {label.replace('|', '&#124;')} | {_value(value)} | {'yes' if met else '**no**'} |"
                  for label, value, met in rows]
        sections.append("\n".join(lines))

    for name, (issue, command) in SUITES.items():
        path, quick = _committed(name, folder)
        if path is not None:
            targets = json.loads(path.read_text()).get("targets", [])
            section(issue, path.name, command + (" --quick" if quick else ""),
                    [(t["target"], t["value"], t["met"]) for t in targets])
    for name, (issue, command) in SELFTESTS.items():
        if (folder / name).is_file():
            s = json.loads((folder / name).read_text())["summary"]
            section(issue, name, command, [
                (f"{s['n_cases']} simulated cases, one random effect or none each: top-1 >= 90 % (share)",
                 s["top1_accuracy"], s["top1_accuracy"] >= 0.9),
                ("the same cases: false alarms (share, target 0)", s["false_alarm_rate"], s["false_alarm_rate"] == 0)])
    return "\n\n".join(sections)


BEGIN, END = "<!-- status-table: python -m adcpdyn.benchmarks.status -->\n", "<!-- /status-table -->"


def write(page: Path, folder: Path = RESULTS) -> None:
    """Replace the table between ``page``'s markers (written atomically, :func:`~adcpdyn.cases.atomic.atomic_path`)."""
    from ..cases.atomic import atomic_path

    text = page.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{page}: expected the markers {BEGIN.strip()!r} and {END!r}")
    i, j = text.index(BEGIN) + len(BEGIN), text.index(END)
    with atomic_path(page, suffix=page.suffix) as tmp:
        tmp.write_text(text[:i] + markdown_table(folder) + "\n" + text[j:])


if __name__ == "__main__":
    if sys.argv[1:2] == ["--write"] and len(sys.argv) == 3:
        write(Path(sys.argv[2]))
    else:
        print(markdown_table(Path(sys.argv[1]) if len(sys.argv) > 1 else RESULTS))
