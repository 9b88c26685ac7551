"""The Typer application: one sub-command per stage module."""

from __future__ import annotations

from typing import Annotated

import typer

from tollcli import __version__
from tollcli.cli.audit import audit
from tollcli.cli.batch import batch
from tollcli.cli.design import design
from tollcli.cli.enforcement import enforce, findings, locate
from tollcli.cli.epochs import epochs
from tollcli.cli.geoobjects import app as geoobjects_app
from tollcli.cli.integrity import integrity
from tollcli.cli.process import process
from tollcli.cli.report import plot, report
from tollcli.cli.simulate import simulate
from tollcli.cli.verify import verify

EPILOG = (
    "Exit codes: 0 ok; 1 data error (input unusable, a bad line under --strict, or verify found a difference); "
    "2 usage error (bad option, missing file, directory); 3 partial (outputs written, more lines skipped than --max-bad)."
)

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


def _version(value: bool) -> None:
    if value:
        typer.echo(f"tollcli {__version__}")
        raise typer.Exit()


@app.callback()
def root(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit."),
    ] = False,
) -> None:
    """GNSS road-user charging log processor."""


for command in (process, audit, verify, epochs, integrity, design, simulate, locate, findings, enforce, plot, report, batch):
    app.command(epilog=EPILOG)(command)
app.add_typer(geoobjects_app, name="geoobjects")
