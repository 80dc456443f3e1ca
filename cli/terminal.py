"""What the verbs say and where: results on stdout and warnings on stderr, wrapped to the tables'
width; one progress line per step on the terminal's stderr (``ADCPDYN_PROGRESS``), even while
descriptor 2 is held (:class:`HeldStderr`)."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import time


from ..text import prose


# ---------------------------------------------------------------------------------- progress on stderr
LIVE_FD: int | None = None  # the real stderr while descriptor 2 is held (see HeldStderr)


def progress_enabled() -> bool:
    """Progress lines on stderr: when it is a terminal, or as ``ADCPDYN_PROGRESS=1|0`` says (stdout stays clean)."""
    from ..progress import progress_enabled as enabled

    return enabled(LIVE_FD if LIVE_FD is not None else 2)


def warn(text: str) -> None:
    """A warning on stderr (stdout keeps the results a script reads), wrapped to the tables' width."""
    print(prose(f"warning: {text}"), file=sys.stderr)


def say(line: str, indent: str = "    ") -> None:
    """A line of results on stdout, wrapped to the tables' width (continuation lines indented)."""
    print(prose(line, indent=indent))


class Progress:
    """One stderr line per step, with the seconds since the command started: ``adcpdyn VERB: [  12.3 s] TEXT``."""

    def __init__(self, verb: str):
        self.verb, self.t0, self.on = verb, time.perf_counter(), progress_enabled()

    def __call__(self, text: str) -> None:
        if not self.on:
            return
        line = f"adcpdyn {self.verb}: [{time.perf_counter() - self.t0:7.1f} s] {text}\n".encode("utf-8", "replace")
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        with contextlib.suppress(OSError):
            os.write(LIVE_FD if LIVE_FD is not None else 2, line)


class DiagnosisProgress(Progress):
    """The diagnosis's labels (``effect`` in round 1, ``chosen+effect`` later) as round, effect and time."""

    def __init__(self, verb: str, n_runs: int):
        super().__init__(verb)
        self.fitted = 0
        self(f"fitting the base model ({n_runs} run{'s' if n_runs > 1 else ''}) and its held-out residuals")

    def fitted_model(self, label: str) -> None:
        if self.fitted == 0:
            self("base model fitted; trying the catalog's effects")
        self.fitted += 1
        parts = label.split("+")
        on_top = f" on top of {'+'.join(parts[:-1])}" if len(parts) > 1 else ""
        self(f"round {len(parts)}: fitted {parts[-1]}{on_top} (model {self.fitted})")


class HeldStderr:
    """File descriptor 2 held in a temporary file while a command runs.

    Solver libraries (CasADi, IPOPT, LAPACK) write their own warnings straight to the
    descriptor. A command that succeeds gets them back afterwards, in order; one that
    ends in a one-line error drops them, so that the error is the only line.
    """

    def __init__(self):
        self._saved = self._sink = None

    def __enter__(self):
        global LIVE_FD
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        try:
            self._saved = os.dup(2)
            self._sink = tempfile.TemporaryFile()
            os.dup2(self._sink.fileno(), 2)
            LIVE_FD = self._saved  # progress lines still reach the terminal (Progress)
        except OSError:
            self._saved = self._sink = None
        return self

    def __exit__(self, *exc):
        global LIVE_FD
        if self._saved is not None:
            with contextlib.suppress(Exception):
                sys.stderr.flush()
            os.dup2(self._saved, 2)
            os.close(self._saved)
            LIVE_FD = None
        return False

    def replay(self) -> None:
        if self._sink is not None:
            self._sink.seek(0)
            data = self._sink.read()
            if data:
                with contextlib.suppress(Exception):
                    sys.stderr.flush()
                os.write(2, data)
            self._sink.close()

    def drop(self) -> None:
        if self._sink is not None:
            self._sink.close()
