"""Atomic output: write to a temporary file beside the target, then rename over it.

The temporary file is named ``.NAME.adcpdyn-tmp-HOST-PID-XXXXXXXX[SUFFIX]`` (NAME the
target's name, HOST and PID the writing process). A process killed while writing
(SIGKILL, power loss) cannot remove it, so every later write into the same folder
removes the temporary files whose process is gone (same host, PID no longer alive):
:func:`remove_stale_temporaries`. Outputs get the permissions the process umask gives a
new file (``0o666 & ~umask``), as ``open(path, "w")`` would, not ``mkstemp``'s 0600.

Command-line outputs are checked before any work: :func:`check_output_file` and
:func:`check_output_folder`.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import tempfile
from pathlib import Path

TMP_TAG = ".adcpdyn-tmp-"
# .NAME.adcpdyn-tmp-HOST-PID-XXXXXXXX[SUFFIX]; mkstemp's random part is 8 of [a-z0-9_]
_TMP_NAME = re.compile(r"^\..+" + re.escape(TMP_TAG) + r"(?P<host>.+)-(?P<pid>\d+)-[a-z0-9_]{8}(?:\.[^.]*)?$")


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_.]", "_", socket.gethostname() or "localhost")


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    except OSError:
        return True
    return True


def current_umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def remove_stale_temporaries(folder) -> list[Path]:
    """Remove this host's atomic-writer temporaries in ``folder`` whose writing process is gone.

    Returns the paths removed. Temporaries of live processes, of other hosts (a shared
    file system) and of this process are kept.
    """
    folder = Path(folder) if str(folder) else Path(".")
    removed = []
    host, me = _host(), os.getpid()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        m = _TMP_NAME.match(entry.name)
        if m is None or m["host"] != host:
            continue
        pid = int(m["pid"])
        if pid == me or _process_alive(pid):
            continue
        with contextlib.suppress(OSError):
            os.unlink(entry.path)
            removed.append(Path(entry.path))
    return removed


def _mkstemp(folder: Path, name: str, suffix: str) -> str:
    fd, tmp = tempfile.mkstemp(prefix=f".{name}{TMP_TAG}{_host()}-{os.getpid()}-", suffix=suffix, dir=folder)
    try:
        os.fchmod(fd, 0o666 & ~current_umask())
    finally:
        os.close(fd)
    return tmp


def same_file(a, b) -> bool:
    """True when two paths name the same existing file."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def refuse_overwrite_input(out_path, *inputs) -> None:
    """Raise ValueError when an output path would overwrite one of the inputs."""
    for src in inputs:
        if src is not None and same_file(out_path, src):
            raise ValueError(f"--out: {out_path} is an input file; choose another output path (inputs are never overwritten)")


def _probe(folder: Path, option: str, target: str) -> None:
    """Create and remove a temporary file in ``folder`` as the atomic writer will."""
    try:
        os.unlink(_mkstemp(folder, "probe", ".tmp"))
    except OSError as exc:
        raise ValueError(f"{option}: {target}: cannot write in folder {folder} ({exc.strerror or exc})") from None


def check_output_file(path, *inputs, option: str = "--out") -> Path:
    """Check, before any work, that an output file can be written where ``path`` says.

    The folder must exist (it is not created: a mistyped folder is an error, not a new
    folder) and be writable, ``path`` must not be a folder, and it must not name one of
    the ``inputs``. Stale temporaries of killed writers in that folder are removed.

    Raises
    ------
    ValueError
        One line naming ``option`` and the path.
    """
    if path is None or str(path).strip() == "":
        raise ValueError(f"{option}: expected a file path, got an empty one")
    p = Path(path)
    refuse_overwrite_input(p, *inputs)
    if p.is_dir():
        raise ValueError(f"{option}: {p} is a folder; expected a file path")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.exists():
        raise ValueError(f"{option}: {p}: folder {folder} does not exist; create it first (outputs are not written "
                         "into new folders)")
    if not folder.is_dir():
        raise ValueError(f"{option}: {p}: {folder} is not a folder")
    _probe(folder, option, str(p))
    remove_stale_temporaries(folder)
    return p


def check_output_folder(path, option: str = "--out") -> Path:
    """Check, before any work, that ``path`` is a writable folder or can be created as one.

    An existing folder must be writable; a missing one must have an existing, writable
    parent (it is created by the first output written into it; deeper missing folders
    are an error). An existing file is refused.

    Raises
    ------
    ValueError
        One line naming ``option`` and the path.
    """
    if path is None or str(path).strip() == "":
        raise ValueError(f"{option}: expected a folder, got an empty path")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{option}: {p} is a file; expected a folder (one output per case)")
    if p.is_dir():
        _probe(p, option, str(p))
        remove_stale_temporaries(p)
        return p
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"{option}: {p}: parent folder {parent} does not exist; create it first")
    _probe(parent, option, str(p))
    return p


@contextlib.contextmanager
def atomic_path(path, suffix=".tmp"):
    """Yield a temporary path in the target's folder; on success it replaces ``path``.

    On any exception (and on SIGTERM/SIGINT, which the command line turns into
    exceptions) the temporary file is removed and ``path`` is left untouched; after a
    SIGKILL the next write into the folder removes it. The output gets the umask's
    permissions.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(folder)
    tmp = _mkstemp(folder, path.name, suffix)
    try:
        yield Path(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
