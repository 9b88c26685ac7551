"""Exceptions that carry a documented exit code.

Exit codes (also in ``tollcli --help`` and the man pages):

* 0 — success
* 1 — data error: the input exists but cannot be used (empty, not NMEA, a bad
  line under ``--strict``)
* 2 — usage error: bad option, missing file, a directory where a file was expected
* 3 — partial: outputs were written, but more lines were skipped than ``--max-bad`` allows
"""

EXIT_OK = 0
EXIT_DATA = 1
EXIT_USAGE = 2
EXIT_PARTIAL = 3


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
