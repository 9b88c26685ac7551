"""Terminal output on stderr: messages and progress (silent with --quiet or off a TTY)."""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager

from rich.console import Console

err = Console(stderr=True, highlight=False, no_color=bool(os.environ.get("NO_COLOR")))


def warn(message: str, quiet: bool = False) -> None:
    """A one-line note on stderr (kept even with --quiet only for errors, never here)."""
    if not quiet:
        err.print(message, markup=False, soft_wrap=True)


@contextmanager
def progress(description: str, quiet: bool):
    """Yield ``advance(n_epochs)``; draws a rich spinner only on an interactive stderr."""
    if quiet or not sys.stderr.isatty():
        yield lambda n: None
        return
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(SpinnerColumn(), TextColumn("{task.description}"), TextColumn("{task.completed} epochs"),
                  TimeElapsedColumn(), console=err, transient=True) as bar:
        task = bar.add_task(description, total=None)
        yield lambda n: bar.advance(task, n)
