"""The ``cmmwb`` command line: the parser of every command (:data:`COMMANDS`, one module each) and
:func:`main`, which runs one and maps failures to exit statuses and one-line messages.

Exit status: 0 success, 2 bad input (one message naming the file and line/key/sheet/cell),
1 an internal error (a bug: please report it with the task file).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import textwrap

from cmmwb.xlfuncs.errors import ModelError

from .. import __version__
from ..errors import InputError, os_error_reason
from ..workbook.atomic import COMMITTED
from . import addin, build, calibrate, demo, diagnose, import_, new, read, recalc, simulate, validate
from .common import examples_epilog

#: the subcommands, in the order ``cmmwb --help`` lists them; each module's ``register(sub)`` adds its
#: parser, whose ``func`` runs it
COMMANDS = (demo, new, build, recalc, read, diagnose, simulate, addin, import_, calibrate, validate)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cmmwb", formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.fill("Task-specific uncertainty of CMM measurements as live spreadsheet "
                                  "workbooks (Forbes 2025, Wojtyla/Plowucha 2023, Forbes 2022).", 79),
        epilog=examples_epilog("cmmwb demo --out cmmwb-demo",
                         "cmmwb new pointcloud --out gauge.toml && cmmwb build gauge.toml --out gauge",
                         "cmmwb COMMAND --help") +
        "\n\nExit status: 0 success, 2 bad input (one message naming the file and line, key, sheet "
        "or cell),\n1 an internal error. Task files, JSON and workbooks: docs/cli.md.")
    p.add_argument("--version", action="version", version=f"cmmwb {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    for command in COMMANDS:
        command.register(sub)
    return p


#: exit status when the reader of stdout left (``cmmwb recalc BOOK | head -1``): 128 + SIGPIPE, what
#: the shell reports for any program stopped by a closed pipe; nothing is printed (docs/cli.md)
EXIT_CLOSED_PIPE = 141


def main(argv: list[str] | None = None) -> int:
    try:
        args = parser().parse_args(argv)
    except SystemExit:      # --help, --version, a usage error: printed by argparse
        if _stdout_flushed():
            raise
        return EXIT_CLOSED_PIPE
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _quiet_unraisable
    previous_int = _catch_sigint()
    previous_term = _catch_termination()
    try:
        code = _run(args)
        return code if _stdout_flushed() else EXIT_CLOSED_PIPE
    finally:
        _cancel_redelivery()
        sys.unraisablehook = previous_hook
        if previous_int is not None:
            signal.signal(signal.SIGINT, previous_int)
        for sig, handler in previous_term.items():
            signal.signal(sig, handler)


_interrupted = False


def _on_sigint(signum, frame):
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


def _catch_sigint():
    """Ctrl-C raises KeyboardInterrupt as usual, and is remembered: a library that turns the
    interruption into another exception (matplotlib does) still ends as 'interrupted', 130."""
    global _interrupted
    _interrupted = False
    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            return signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:           # not the main thread
        pass
    return None


_terminated_by = 0


def _on_termination(signum, frame):
    """SIGTERM or SIGHUP (``kill``, a closed terminal): end like Ctrl-C, so that a build removes
    its staging folder instead of leaving it behind; exit status 128 + the signal's number."""
    global _terminated_by
    _terminated_by = signum
    raise KeyboardInterrupt


def _catch_termination() -> dict:
    """Install :func:`_on_termination` for SIGTERM and SIGHUP where they have their default
    disposition; the previous handlers, to restore."""
    global _terminated_by
    _terminated_by = 0
    previous = {}
    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        try:
            if sig is not None and signal.getsignal(sig) is signal.SIG_DFL:
                previous[sig] = signal.signal(sig, _on_termination)
        except ValueError:       # not the main thread
            pass
    return previous


def _interrupted_line() -> str:
    """'interrupted', and where the command had already written its complete outputs (a signal
    held back during the commit is delivered once it is complete)."""
    if not COMMITTED:
        return "cmmwb: interrupted"
    return ("cmmwb: interrupted after its outputs were written, complete, into "
            + ", ".join(str(d) for d in dict.fromkeys(COMMITTED)))


def _run(args) -> int:
    """Run a command; every failure a user can cause is one line on stderr and exit status 2
    (130 for Ctrl-C; a closed output pipe ends quietly), never a traceback."""
    COMMITTED.clear()
    try:
        return args.func(args)
    except InputError as e:
        return _fail(str(e))
    except ModelError as e:
        return _fail(str(e))
    except KeyboardInterrupt:
        print(_interrupted_line(), file=sys.stderr)
        return 128 + _terminated_by if _terminated_by else 130
    except BrokenPipeError:
        _silence_stdout()        # `cmmwb recalc book.xlsx | head`: the reader left; nothing to say
        return EXIT_CLOSED_PIPE
    except OSError as e:         # disk full, read-only folder, permission denied, ...
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        return _fail(f"{where}cannot write or read: {os_error_reason(e)}; the previous output is unchanged")
    except MemoryError:
        return _fail("not enough memory for this task (see docs/input_limits.md for the sizes that fit)")
    except RecursionError:
        return _fail("the input is nested too deeply to process")
    except Exception as e:  # a bug: say so plainly
        if _interrupted or _terminated_by:
            print(_interrupted_line(), file=sys.stderr)
            return 128 + _terminated_by if _terminated_by else 130
        if os.environ.get("CMMWB_DEBUG"):
            raise
        print(f"cmmwb: internal error ({type(e).__name__}: {e}); rerun with CMMWB_DEBUG=1 for a "
              "traceback and please report it", file=sys.stderr)
        return 1


def _fail(message: str) -> int:
    try:
        print(f"cmmwb: error: {message}", file=sys.stderr)
    except (OSError, ValueError):
        pass
    return 2


def _stdout_flushed() -> bool:
    """Flush stdout now, inside the command, rather than at interpreter exit (where a closed pipe
    is 'Exception ignored ... BrokenPipeError' and exit status 120); False if the reader left."""
    try:
        sys.stdout.flush()
        return True
    except BrokenPipeError:
        _silence_stdout()
        return False
    except (OSError, ValueError, AttributeError):
        return True


def _silence_stdout() -> None:
    """After a broken pipe, point stdout at /dev/null so that flushing at exit raises nothing."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def _quiet_unraisable(unraisable) -> None:
    """An OSError in a destructor (``ZipFile.__del__`` after a full disk) has already been reported
    as a message; it must not print a traceback too.  A Ctrl-C that landed in a callback whose
    exceptions Python ignores (a weakref callback of the import machinery, a destructor) would be
    lost: it is delivered again, so it surfaces in the command and ends it as 'interrupted'."""
    if isinstance(unraisable.exc_value, OSError):
        return
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        import threading

        # a real SIGINT to the main thread, sent from another thread so that it arrives after this
        # hook has returned (raised in here it would be ignored as well) and wakes a blocking call
        main_thread = threading.main_thread().ident
        timer = threading.Timer(0.01, signal.pthread_kill, (main_thread, signal.SIGINT))
        timer.daemon = True
        _redelivery.append(timer)
        timer.start()
        return
    sys.__unraisablehook__(unraisable)


#: timers delivering a Ctrl-C again (:func:`_quiet_unraisable`); cancelled when the command ends
_redelivery: list = []


def _cancel_redelivery() -> None:
    """A re-delivery still pending when the command has ended must not fire: its thread would send
    the signal while the interpreter shuts down.  (Seen once under heavy load: SIGABRT with 'Fatal
    Python error: PyThreadState_Get ... finalizing' right after 'cmmwb: interrupted'; a timer
    thread still alive at shutdown is the one thread of cmmwb's own that could do that.)"""
    while _redelivery:
        timer = _redelivery.pop()
        timer.cancel()
        timer.join()
