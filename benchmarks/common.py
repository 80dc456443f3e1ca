"""Shared pieces of the benchmark suites: machine record, targets, JSON and figures."""

from __future__ import annotations

import json
import os
import platform
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np


def real_dir() -> Path:
    """The real instrument files: ``ADCPDYN_REAL_DATA``, default ../shared/data/real."""
    return Path(os.environ.get("ADCPDYN_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real"))


def real_cases(names, missing: list):
    """(name, path, imported case) of each real file there; a missing one is appended to ``missing``."""
    from .. import api

    for name in names:
        path = real_dir() / name
        if not path.exists():
            missing.append(str(path))
            continue
        yield name, path, api.import_file(path).case


def machine() -> dict:
    """CPU count, platform and the versions that matter for the figures."""
    return {"python": platform.python_version(), "casadi": ca.__version__, "numpy": np.__version__,
            "machine": platform.machine(), "cpus": os.cpu_count(), "platform": platform.platform()}


@dataclass(frozen=True)
class Target:
    """One issue target: label, measured value and whether it was met."""

    label: str
    value: float
    met: bool

    def to_dict(self) -> dict:
        return {"target": self.label, "value": float(self.value), "met": bool(self.met)}


def print_targets(res: dict, targets: list[Target]) -> None:
    """Print verdicts and store them in ``res["targets"]`` (never asserted)."""
    print("\ntargets")
    for t in targets:
        print(f"  [{'met' if t.met else 'NOT met'}] {t.label}: {t.value:.4g}")
    res["targets"] = [t.to_dict() for t in targets]


def timed_calibration(case, fit=None, **config):
    """(result, setup seconds, solve seconds) of one calibration, warnings silenced."""
    from ..estimators.calibration.config import CalibrationConfig
    from ..estimators.calibration.problem import CalibrationProblem

    tic = time.perf_counter()
    problem = CalibrationProblem(case, CalibrationConfig(**config), fit=fit)
    setup = time.perf_counter() - tic
    tic = time.perf_counter()
    result = problem.solve()
    return result, setup, time.perf_counter() - tic


def json_from_child(code: str, time_limit_s: float, cwd=None, env: dict | None = None) -> tuple[dict | None, str]:
    """Run ``python -c code`` in its own session; (the JSON of its last stdout line, "") or (None,
    why not). Past ``time_limit_s`` the child's whole process group (a compiler too) is killed."""
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=cwd, start_new_session=True, env=None if env is None else {**os.environ, **env})
    try:
        out, err = proc.communicate(timeout=time_limit_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return None, f"did not finish within {time_limit_s:.0f} s"
    lines = out.strip().splitlines()
    if proc.returncode != 0 or not lines:
        last = [ln for ln in err.strip().splitlines() if ln.strip()]
        return None, f"process exited with status {proc.returncode}" + (f": {last[-1][:160]}" if last else "")
    return json.loads(lines[-1]), ""


def write_json(res: dict, path: Path) -> None:
    """The suite's figures as JSON, written atomically."""
    from ..cases.atomic import atomic_path
    from ..estimators.calibration.result import jsonable

    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(jsonable(res), fh, indent=2)


def write_text(text: str, path: Path) -> None:
    """A text file (a markdown table), written atomically."""
    from ..cases.atomic import atomic_path

    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)


def marked_span(path: Path, begin: str, end: str) -> tuple[list, int, int]:
    """A text file's lines and the indices of its ``begin`` and ``end`` marker lines (each once, in order)."""
    path = Path(path)
    lines = path.read_text().splitlines(keepends=True)
    found = [i for i, ln in enumerate(lines) if ln.strip() == begin], [i for i, ln in enumerate(lines) if ln.strip() == end]
    if len(found[0]) != 1 or len(found[1]) != 1 or found[0][0] > found[1][0]:
        raise ValueError(f"--readme: {path} needs the line {begin!r} once, then {end!r} once "
                         f"(found {len(found[0])} and {len(found[1])})")
    return lines, found[0][0], found[1][0]


def replace_marked_block(path: Path, begin: str, end: str, text: str) -> None:
    """Replace what lies between the lines ``begin`` and ``end`` of a text file (a README) with
    ``text``, atomically; the markers stay."""
    lines, i, j = marked_span(path, begin, end)
    block = text if text.endswith("\n") else text + "\n"
    write_text("".join(lines[:i + 1]) + block + "".join(lines[j:]), Path(path))


def integer_ticks(axis) -> None:
    """Ticks at whole numbers only, for an axis that counts (transects, cases, pings): never "1.5 transects"."""
    from matplotlib.ticker import MaxNLocator

    axis.set_major_locator(MaxNLocator(integer=True))


def run_worker(module: str, args: list, time_limit_s: float, env: dict | None = None) -> tuple:
    """``python -m adcpdyn.benchmarks.MODULE ARGS`` in a child process (its peak memory its own):
    (the JSON of its last stdout line, None) or (None, why it gave none: the time limit, or its exit
    status and last stderr line)."""
    cmd = [sys.executable, "-m", f"adcpdyn.benchmarks.{module}", *map(str, args)]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=time_limit_s,
                             env=None if env is None else {**os.environ, **env})
    except subprocess.TimeoutExpired:
        return None, f"exceeded the time limit of {time_limit_s:.0f} s"
    if out.returncode != 0:
        tail = out.stderr.strip().splitlines()[-1] if out.stderr.strip() else ""
        return None, f"worker exited with status {out.returncode}: {tail}"
    return json.loads(out.stdout.strip().splitlines()[-1]), None


def save_figure(fig, path: Path) -> None:
    """Save a matplotlib figure atomically and close it."""
    import matplotlib.pyplot as plt

    from ..cases.atomic import atomic_path

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
