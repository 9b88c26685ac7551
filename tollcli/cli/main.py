"""Entry point: run the app; errors become one line on stderr and an exit code."""

from __future__ import annotations

import os
import sys

from tollcli.errors import EXIT_DATA, TollError


def main(argv: list[str] | None = None) -> None:
    from tollcli.cli.app import app

    try:
        app(args=argv, prog_name="tollcli", standalone_mode=True)
    except TollError as exc:
        sys.stderr.write(f"tollcli: error: {exc}\n")
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        sys.stderr.write("tollcli: interrupted\n")
        sys.exit(130)
    except BrokenPipeError:  # downstream of a pipe closed early (e.g. | head)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        sys.exit(0)
    except MemoryError:
        sys.stderr.write("tollcli: error: out of memory\n")
        sys.exit(EXIT_DATA)
