"""Which IPOPT linear solvers load in the installed CasADi (each probed in a child process,
since a missing HSL library can take the interpreter down)."""

from __future__ import annotations

import subprocess
import sys

CANDIDATES = ("mumps", "ma27", "ma57", "ma77", "ma86", "ma97", "spral", "pardiso")

_PROBE = """
import casadi as ca
x = ca.SX.sym("x", 2)
s = ca.nlpsol("s", "ipopt", {"x": x, "f": ca.sumsqr(x - 1), "g": x[0] + x[1]},
              {"ipopt.linear_solver": "%s", "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"})
s(x0=[0, 0], lbg=1, ubg=1)
print(s.stats()["return_status"])
"""


def probe_linear_solver(name: str, timeout_s: float = 60.0) -> tuple[bool, str]:
    """(loads and solves a tiny NLP, note) for one IPOPT linear solver."""
    try:
        out = subprocess.run([sys.executable, "-c", _PROBE % name], capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return False, f"probe timed out after {timeout_s:.0f} s"
    status = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""
    if out.returncode != 0:
        return False, f"probe process exited with status {out.returncode}"
    if status != "Solve_Succeeded":
        return False, f"IPOPT reports {status or 'nothing'} (library not in this CasADi build)"
    return True, "loads and solves"


def available_linear_solvers(candidates=CANDIDATES) -> dict:
    """``{name: {"available": bool, "note": str}}`` for every candidate."""
    return {n: dict(zip(("available", "note"), probe_linear_solver(n))) for n in candidates}
