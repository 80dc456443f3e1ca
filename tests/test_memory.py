"""numpy's huge-page advice: off once adcpdyn is imported, unless NUMPY_MADVISE_HUGEPAGE decides."""

import os
import subprocess
import sys

import pytest

CODE = """
import numpy
try:
    from numpy._core.multiarray import _get_madvise_hugepage
except ImportError:
    from numpy.core.multiarray import _get_madvise_hugepage
before = _get_madvise_hugepage()
import adcpdyn
print(int(before), int(_get_madvise_hugepage()))
"""


def _run(env_value):
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if env_value is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = env_value
    out = subprocess.run([sys.executable, "-c", CODE], env=env, capture_output=True, text=True, check=True)
    return tuple(int(v) for v in out.stdout.split())


def test_import_turns_numpy_huge_pages_off():
    before, after = _run(None)
    if not before:
        pytest.skip("numpy does not advise huge pages here (old kernel or numpy): nothing to turn off")
    assert after == 0


@pytest.mark.parametrize("value", ["0", "1"])
def test_numpy_own_switch_is_left_as_numpy_read_it(value):
    before, after = _run(value)
    assert after == before
