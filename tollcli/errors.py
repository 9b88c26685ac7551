"""Exceptions that carry a documented exit code.

Exit codes (also in ``tollcli --help`` and the man pages):

* 0 — success
* 1 — data error: the input exists but cannot be used (empty, not NMEA, a bad
  line under ``--strict``)
* 2 — usage error: bad option, missing file, a directory where a file was expected
* 3 — partial: outputs were written, but more lines were skipped than ``--max-bad`` allows
* 4 — system error: a file could not be written or read (read-only folder, disk full,
  permissions); nothing half-written is left in place of an output
* 5 — internal error: a defect of tollcli (the message names it; please report it;
  ``TOLLCLI_DEBUG=1`` shows the traceback)
* 6 — some failed: ``batch`` wrote every log's outputs it could, but some logs failed (``failed/`` says why); when
  the system refused a log's files (disk full), ``batch`` exits 4
"""

EXIT_OK = 0
EXIT_DATA = 1
EXIT_USAGE = 2
EXIT_PARTIAL = 3
EXIT_SYSTEM = 4
EXIT_INTERNAL = 5
EXIT_SOME_FAILED = 6


class TollError(Exception):
    """An error reported to the user as one line, with an exit code."""

    exit_code = EXIT_DATA


class DataError(TollError):
    """The input is there but unusable."""

    exit_code = EXIT_DATA


class UsageError(TollError):
    """The command line asks for something impossible (missing file, bad option)."""

    exit_code = EXIT_USAGE


class PartialError(TollError):
    """The job finished and wrote its outputs, but more input was skipped than allowed (--max-bad)."""

    exit_code = EXIT_PARTIAL


class SystemFailureError(TollError):
    """The system refused a file (disk full, permissions): what could be written was, nothing is half-written."""

    exit_code = EXIT_SYSTEM


class SomeFailedError(TollError):
    """A batch finished and wrote the outputs of the logs it could; some logs failed."""

    exit_code = EXIT_SOME_FAILED
