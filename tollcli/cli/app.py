"""The Typer application: one sub-command per stage module."""

from __future__ import annotations

from typing import Annotated

import typer

from tollcli import __version__

#: command name → (module, function); a module is imported only when its command is built
COMMANDS = {
    "process": ("tollcli.cli.process", "process"), "audit": ("tollcli.cli.audit", "audit"),
    "verify": ("tollcli.cli.verify", "verify"), "epochs": ("tollcli.cli.epochs", "epochs"),
    "integrity": ("tollcli.cli.integrity", "integrity"), "design": ("tollcli.cli.design", "design"),
    "simulate": ("tollcli.cli.simulate", "simulate"), "locate": ("tollcli.cli.enforcement", "locate"),
    "findings": ("tollcli.cli.enforcement", "findings"), "enforce": ("tollcli.cli.enforcement", "enforce"),
    "plot": ("tollcli.cli.report", "plot"), "report": ("tollcli.cli.report", "report"),
    "batch": ("tollcli.cli.batch", "batch"), "info": ("tollcli.cli.info", "info"),
    "geoobjects": ("tollcli.cli.geoobjects", "app"), "osnma": ("tollcli.cli.osnma", "osnma"),
}  # fmt: skip

EPILOG = (
    "Exit codes: 0 ok; 1 data error (input unusable, a bad line under --strict, or verify found a difference); "
    "2 usage error (bad option, missing file, directory); 3 partial (outputs written, more lines skipped than --max-bad); "
    "4 system error (an output cannot be written: read-only, disk full); 5 internal error (a defect: please report it); "
    "6 some logs of a batch failed (the others' outputs written; failed/ says why)."
)

def _version(value: bool) -> None:
    if value:
        typer.echo(f"tollcli {__version__}")
        raise typer.Exit()


def root(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit."),
    ] = False,
) -> None:
    """GNSS road-user charging log processor."""


def build_app(only: str | None = None) -> typer.Typer:
    """The application with every command, or with just ``only`` (what ``tollcli CMD`` needs: a fast start; "" none)."""
    import importlib

    app = typer.Typer(
        name="tollcli",
        help="GNSS road-user charging log processor: receiver logs → trusted epochs → geo-objects → invoices.",
        epilog=EPILOG,
        no_args_is_help=True,
        add_completion=True,
        pretty_exceptions_enable=False,
        rich_markup_mode=None,
        context_settings={"help_option_names": ["-h", "--help"]},
    )
    app.callback()(root)
    for name, (module, attr) in COMMANDS.items():
        if only is not None and name != only:
            continue
        command = getattr(importlib.import_module(module), attr)
        if name == "geoobjects":
            app.add_typer(command, name="geoobjects")
        else:
            app.command(epilog=EPILOG)(command)
    return app


def __getattr__(name: str):
    if name == "app":  # the whole application (tests, man pages, completion)
        return build_app()
    raise AttributeError(name)
