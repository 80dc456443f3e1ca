"""``adcpdyn``: parse, run the verb, and end with the exit status the parser's epilog lists; a
user-facing error in one line, SIGTERM and Ctrl-C leaving no partial file."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading


from .parser import build_parser
from .terminal import HeldStderr


class Terminated(BaseException):
    """SIGTERM as an exception, so that atomic writers remove their temporary files."""


def _terminate(signum, frame):
    raise Terminated(f"terminated by signal {signum}")


@contextlib.contextmanager
def _sigterm_as_exception():
    """Turn SIGTERM into :class:`Terminated` while a command runs (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def _holds_stderr(args) -> bool:
    """Not for what shows progress on stderr: the self-test, benchmarks, many cases."""
    from ..cases.collect import is_many

    if getattr(args, "selftest", None) or args.command in ("bench", "demo"):
        return False
    case = getattr(args, "case", None)
    return not (isinstance(case, list) and is_many(case))


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help (0) or an option error, said in one line by the parser (2)
        return int(exc.code or 0)
    held = HeldStderr() if _holds_stderr(args) else contextlib.nullcontext()
    error = None
    try:
        with _sigterm_as_exception(), held:
            code = args.func(args)
    except BrokenPipeError:  # the reader stopped reading (`| head`): quiet, as a shell's SIGPIPE death
        with contextlib.suppress(OSError, ValueError):  # nothing more to flush at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 128 + signal.SIGPIPE
    except (ValueError, OSError) as exc:
        # CaseFormatError is a ValueError; every user-facing error is one line.
        error, code = f"adcpdyn {args.command}: error: {_one_line(exc)}", 2
    except Terminated as exc:
        error, code = f"adcpdyn {args.command}: {exc}; stopped (no partial file left)", 128 + signal.SIGTERM
    except KeyboardInterrupt:
        error, code = f"adcpdyn {args.command}: interrupted; stopped (no partial file left)", 128 + signal.SIGINT
    except BaseException:
        if isinstance(held, HeldStderr):
            held.replay()
        raise
    if isinstance(held, HeldStderr):
        held.drop() if error else held.replay()
    if error:
        print(error, file=sys.stderr)
    return code
