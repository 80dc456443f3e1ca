"""The field's reader: ``mhkit.dolfyn`` (imported lazily; it is heavy and optional).

The standalone ``dolfyn`` 1.3.0 fails with numpy 2; the copy inside MHKiT (pinned in
the ``io`` extra) works, so that is the one used.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import sys
import tempfile
import threading
import warnings

# WinRiver II stores GGA latitude and longitude as float64; dolfyn keeps them as float32
# (about 1 m of resolution). These entries are read with float64 storage instead.
FLOAT64_FIELDS = ("latitude_gps", "longitude_gps")


class ImportFailure(ValueError):
    """A file cannot be imported; the message is one line naming what is missing."""


class Chatter:
    """What a reader said while it ran: log records, warnings and C-level output (one entry per line)."""

    def __init__(self):
        self.messages: list[str] = []

    def summary(self) -> str | None:
        """One line: how many messages were kept out of the terminal, and the first (None if none)."""
        if not self.messages:
            return None
        first = self.messages[0] if len(self.messages[0]) <= 100 else self.messages[0][:97] + "..."
        return (f"{len(self.messages)} message(s) of the file reader (dolfyn log, warnings, LAPACK) kept out of the "
                f"terminal; first: {first}")


class _Collect(logging.Handler):
    def __init__(self, chatter: Chatter):
        super().__init__(logging.DEBUG)
        self.chatter = chatter

    def emit(self, record):
        with contextlib.suppress(Exception):
            self.chatter.messages.append(" ".join(record.getMessage().split()))


@contextlib.contextmanager
def _fd_capture(chatter: Chatter):
    """Route file descriptors 1 and 2 into a temporary file (C libraries write there directly)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no terminal descriptors: nothing to keep out
        yield
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            yield
        finally:
            for stream in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    stream.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace")
            chatter.messages.extend(" ".join(line.split()) for line in text.splitlines() if line.strip())


@contextlib.contextmanager
def quiet_reader():
    """Keep the reader's chatter out of the terminal, and count it.

    dolfyn and MHKiT log to the root logger (checksum errors, unknown ID codes) and warn;
    LAPACK prints ``** On entry to DLASCL ...`` lines on file descriptor 1 when handed NaN.
    Inside the block all of that goes into the yielded :class:`Chatter` instead (the root
    logger's handlers are swapped for a collector, warnings are recorded, descriptors 1 and
    2 go to a temporary file). Exceptions pass through untouched; an ImportFailure gets
    the reader's first message appended, so that a damaged file's error says where.
    """
    chatter = Chatter()
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    collector = _Collect(chatter)
    root.handlers = [collector]
    root.setLevel(logging.WARNING)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                if threading.current_thread() is threading.main_thread():
                    with _fd_capture(chatter):
                        yield chatter
                else:
                    yield chatter
            finally:
                chatter.messages.extend(" ".join(str(w.message).split()) for w in caught)
    except ImportFailure as exc:
        if chatter.messages:
            more = f" (+{len(chatter.messages) - 1} more)" if len(chatter.messages) > 1 else ""
            raise ImportFailure(f"{exc}; the reader reported: {chatter.messages[0][:120]}{more}") from exc.__cause__
        raise
    finally:
        root.handlers = handlers
        root.setLevel(level)


def reader_version() -> str:
    """``mhkit <version>`` (the dolfyn inside it), or raise ImportFailure when absent."""
    try:
        import mhkit
    except ImportError as exc:
        raise ImportFailure("reading instrument files needs mhkit (the dolfyn reader): "
                            "pip install 'adcpdyn[io]'") from exc
    return f"mhkit {mhkit.__version__} (mhkit.dolfyn)"


@contextlib.contextmanager
def _float64_gnss():
    from mhkit.dolfyn.io import rdi_defs

    saved = {k: rdi_defs.data_defs[k] for k in FLOAT64_FIELDS}
    try:
        for k, d in saved.items():
            rdi_defs.data_defs[k] = (d[0], d[1], "float64", *d[3:])
        yield
    finally:
        rdi_defs.data_defs.update(saved)


def read_dolfyn(path):
    """Read an instrument file with dolfyn; any failure becomes a one-line ImportFailure.

    Returns
    -------
    (xarray.Dataset, str)
        The dataset and the reader's version text.
    """
    version = reader_version()
    from mhkit import dolfyn

    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()), _float64_gnss():
            warnings.simplefilter("ignore")
            ds = dolfyn.read(str(path))
    except Exception as exc:  # the reader's own failure, reported in one line
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise ImportFailure(f"{path}: {version} could not read the file ({type(exc).__name__}: {text}); "
                            "adcpdyn has no reader of its own for it") from exc
    return ds, version
