"""Entry point: run the app; errors become one line on stderr and an exit code."""

from __future__ import annotations

import gc
import os
import signal
import sys
import threading

import typer

from tollcli.cli import coercion
from tollcli.errors import EXIT_DATA, EXIT_INTERNAL, EXIT_SYSTEM, EXIT_USAGE, TollError


def _fail(message: str, code: int) -> None:
    message = " ".join(message.split())  # one line, whatever a library's message held
    sys.stderr.write(f"tollcli: error: {message}\n")
    sys.exit(code)


class Terminated(BaseException):
    """SIGTERM arrived: unwind like an interrupt, so that every output being written is discarded."""


def _on_sigterm(signum, frame) -> None:
    raise Terminated()


def _reader_gone() -> None:
    """The reader of our stdout went away (``| head``): not an error; exit 0 without a word."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    sys.exit(0)


def _say_cache_notes() -> None:
    """A cache that is not used is said once per message on stderr, as a note (the run goes on without it)."""
    import warnings

    from tollcli.cache import CacheNotUsed

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, CacheNotUsed):
            sys.stderr.write(f"tollcli: note: {' '.join(str(message).split())}\n")
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show
    warnings.simplefilter("once", CacheNotUsed)


def main(argv: list[str] | None = None) -> None:
    from tollcli.cli.app import COMMANDS, build_app

    _say_cache_notes()

    args = sys.argv[1:] if argv is None else argv
    first = next((a for a in args if not a.startswith("-")), None)
    lean = first in COMMANDS and "--install-completion" not in args and "--show-completion" not in args
    if first is None and "--version" in args:
        lean, first = True, ""  # no command needed
    listing = first is None and not lean and "--install-completion" not in args and "--show-completion" not in args
    whole_process = argv is None  # the command line's own run (a caller's process keeps its collector as it is)
    collecting = gc.isenabled()
    if whole_process:  # the command's imports make objects by the hundred thousand and free almost none: no
        gc.disable()  # collection runs among them, and none scans them after (0.1 s of a `process`)
    try:
        app = build_app(first if lean else None, listing=listing)  # (no command given: its help, from the summaries)
    finally:
        if whole_process:
            gc.freeze()  # modules, functions and classes live as long as the process
            if collecting:
                gc.enable()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _on_sigterm)

    coercion.install()  # plain option values typed without pydantic (0.13 s of every start)

    try:
        code = app(args=argv, prog_name="tollcli", standalone_mode=False)
    except TollError as exc:
        _fail(str(exc), exc.exit_code)
    except typer.TyperException as exc:  # usage errors: bad option, missing argument, bad value
        ctx = getattr(exc, "ctx", None)
        if type(exc).__name__ == "NoArgsIsHelpError":  # bare `tollcli`: the help, as click shows it
            sys.stderr.write(exc.format_message() + "\n")
            sys.exit(EXIT_USAGE)
        where = ctx.command_path if ctx is not None else "tollcli"
        message = exc.format_message().replace(": Value error, ", ": ")  # (pydantic's words for a choice not made)
        _fail(f"{message} (see '{where} --help')", exc.exit_code or EXIT_USAGE)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except typer.Abort as exc:
        if isinstance(exc.__cause__, EOFError):  # click turns an end of input into Abort: it is the data's, not the user's
            _fail(f"unexpected end of input ({exc.__cause__})", EXIT_DATA)
        sys.stderr.write("tollcli: interrupted\n")
        sys.exit(130)
    except KeyboardInterrupt:
        sys.stderr.write("tollcli: interrupted\n")
        sys.exit(130)
    except Terminated:
        sys.stderr.write("tollcli: terminated\n")
        sys.exit(143)
    except BrokenPipeError:  # downstream of a pipe closed early (e.g. | head)
        _reader_gone()
    except SystemExit as exc:
        # click answers a closed pipe with exit 1 after swapping stdout for its PacifyFlushWrapper
        if exc.code == 1 and type(sys.stdout).__name__ == "PacifyFlushWrapper":
            _reader_gone()
        raise
    except MemoryError:
        _fail("out of memory", EXIT_DATA)
    except RecursionError:
        _fail("an input is nested too deeply to read", EXIT_DATA)
    except OSError as exc:  # the system refused a file: read-only folder, disk full, permissions
        where = f"{exc.filename}: " if exc.filename else ""
        _fail(f"{where}{exc.strerror or exc}", EXIT_SYSTEM)
    except Exception as exc:  # noqa: BLE001 - a defect: one line and its own exit code, the traceback on request
        if os.environ.get("TOLLCLI_DEBUG"):
            raise
        _fail(f"internal error ({type(exc).__name__}: {exc}); please report it (TOLLCLI_DEBUG=1 shows where)", EXIT_INTERNAL)
    sys.exit(code if isinstance(code, int) else 0)
