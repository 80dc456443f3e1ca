"""CasADi Functions compiled to machine code once per machine, kept in a cache folder you can see.

CasADi generates the C code of a Function (with its first-order reverse derivative when a
solver's gradient goes through it); the code's hash, with the compiler command and CasADi's
version (and the CPU, for code built for its instruction set: ``NATIVE_FLAGS``, IEEE arithmetic
kept), names a shared library in the cache folder. The system C compiler builds it there the
first time (written under a temporary name, then renamed: parallel workers never see half a
library) and ``casadi.external`` loads it from then on, so one compilation serves every case,
process and worker that uses the same per-ping model. The folder is ``$ADCPDYN_CACHE``, else
``$XDG_CACHE_HOME/adcpdyn/compiled``, else ``~/.cache/adcpdyn/compiled``; ``adcpdyn cache`` lists
it and ``adcpdyn cache --clear`` empties it. Without a compiler, or when compiling fails, the
Function is returned as it was (interpreted: the same numbers, slower) and the reason is kept.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

import casadi as ca

CACHE_ENV = "ADCPDYN_CACHE"
PORTABLE_FLAGS = ("-O2", "-fPIC", "-shared")
# this CPU's instruction set (VEX-encoded code calling libm's AVX/FMA variants of sin, cos and exp) with IEEE
# arithmetic kept (no fused multiply-add contraction: the numbers stay the interpreted ones): the exact per-ping
# solve on 10^5 deep_ocean pings 0.124 -> 0.102 s, the closed form 0.067 -> 0.047 s
NATIVE_FLAGS = ("-O2", "-march=native", "-ffp-contract=off", "-fPIC", "-shared")
SUFFIX = ".so"

last_failure: str | None = None  # why the last compilation fell back to the interpreted Function
MAX_LOADED = 64  # loaded libraries kept for reuse (by the Function's serialized form)
_loaded: dict = {}  # (serialized hash, reverse, cache folder, compiler) -> (library path, the loaded Function)
_loaded_lock = threading.Lock()


def cache_dir() -> Path:
    """The cache folder (not created here)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "adcpdyn" / "compiled"


def compiler() -> str | None:
    """The C compiler (``$CC``, else gcc or cc on PATH), or None."""
    for name in (os.environ.get("CC"), "gcc", "cc"):
        found = shutil.which(name) if name else None
        if found:
            return found
    return None


def available() -> bool:
    return compiler() is not None


@functools.lru_cache(maxsize=4)
def _flags_for(cc: str) -> tuple:
    """NATIVE_FLAGS if ``cc`` builds a library with them (some compilers or targets refuse
    ``-march=native``), else PORTABLE_FLAGS."""
    with tempfile.TemporaryDirectory(prefix="adcpdyn-cc-") as tmp:
        source = Path(tmp) / "probe.c"
        source.write_text("double probe(double x) { return x * x; }\n")
        done = subprocess.run([cc, *NATIVE_FLAGS, str(source), "-o", str(Path(tmp) / "probe.so")], capture_output=True)
    return NATIVE_FLAGS if done.returncode == 0 else PORTABLE_FLAGS


def flags() -> tuple:
    """The compiler flags the cache's libraries are built with on this machine."""
    cc = compiler()
    return _flags_for(cc) if cc else PORTABLE_FLAGS


@functools.lru_cache(maxsize=1)
def _cpu() -> str:
    """This CPU's identity (model and instruction-set flags): a library built for it is not loaded
    on another CPU sharing the cache folder (a home directory on a network file system)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor()
    first = text.split("\n\n", 1)[0]
    return "\n".join(line for line in first.splitlines() if line.split(":")[0].strip() in ("vendor_id", "model name", "flags"))


def library_path(fun: ca.Function, reverse: bool = False) -> tuple[Path, str]:
    """Where ``fun``'s library lives in the cache, and its C code."""
    gen = ca.CodeGenerator(f"{fun.name()}.c", {"with_header": False})
    gen.add(fun)
    if reverse:
        gen.add(fun.reverse(1))  # named adj1_<name>: casadi.external finds it for the gradient
    code = gen.dump()
    build = flags()
    cpu = _cpu() if build == NATIVE_FLAGS else ""
    key = hashlib.sha256("\n".join([code, compiler() or "", *build, ca.__version__, platform.machine(), cpu]).encode())
    return cache_dir() / f"{fun.name()}_{key.hexdigest()[:20]}{SUFFIX}", code


def compiled(fun: ca.Function, reverse: bool = False) -> ca.Function:
    """``fun`` as a compiled library from the cache (built there if missing), with its reverse
    derivative when ``reverse``; ``fun`` itself when it cannot be compiled (:data:`last_failure`).

    A Function built again with the same expressions (its serialized form: a diagnosis builds
    the same per-ping model for each of its dozens of candidate models) gets the library loaded
    the first time, the same Function object: neither its C code generated again to find the
    library (8 ms) nor its derivatives derived again by CasADi, which keeps them with the object.
    """
    cc = compiler()
    if cc is None:
        global last_failure
        last_failure = "no C compiler (gcc, cc or $CC) on PATH"
        return fun
    key = (hashlib.sha256(fun.serialize().encode()).hexdigest(), reverse, str(cache_dir()), cc)
    with _loaded_lock:
        hit = _loaded.get(key)
        if hit is not None and hit[0].exists():
            return hit[1]
        out, path = _load(fun, reverse, cc)
        if path is not None:
            if len(_loaded) >= MAX_LOADED:
                _loaded.clear()
            _loaded[key] = (path, out)
        return out


def _load(fun: ca.Function, reverse: bool, cc: str) -> tuple[ca.Function, Path | None]:
    """(the loaded library's Function, its path), building it into the cache if missing; (``fun``, None)
    when it cannot be built."""
    global last_failure
    path, code = library_path(fun, reverse)
    if not path.exists():
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=path.parent, prefix=".build-") as tmp:
                source, lib = Path(tmp) / f"{fun.name()}.c", Path(tmp) / path.name
                source.write_text(code)
                done = subprocess.run([cc, *flags(), str(source), "-o", str(lib), "-lm"], capture_output=True, text=True)
                if done.returncode != 0:
                    last_failure = f"{cc} failed on {fun.name()}: {done.stderr.strip().splitlines()[-1:]}"
                    return fun, None
                os.replace(lib, path)  # atomic: another worker's identical library may land first
        except OSError as err:
            last_failure = f"cannot write the cache {path.parent}: {err}"
            return fun, None
    return ca.external(fun.name(), str(path)), path


def entries() -> list[Path]:
    """The cached libraries, newest first."""
    folder = cache_dir()
    if not folder.is_dir():
        return []
    return sorted(folder.glob(f"*{SUFFIX}"), key=lambda p: p.stat().st_mtime, reverse=True)


def clear() -> int:
    """Delete the cached libraries; returns how many."""
    found = entries()
    with _loaded_lock:
        _loaded.clear()
    for p in found:
        p.unlink(missing_ok=True)
    return len(found)
