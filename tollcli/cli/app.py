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

#: each command's help up to its first blank line, as ``tollcli --help`` lists it: the top-level help is drawn from
#: these without importing any command (and so no numpy, pandas or scipy); tested equal to the commands' own
SUMMARIES = {
    "process": "Charge a trip: valid, independent positions inside geo-objects → invoice lines with evidence.",
    "audit": "Count undercharges (driven, not charged) and overcharges (charged, not driven) with rates and 95 % intervals.",
    "verify": "Check the invoice's own hash and its inputs' hashes, re-run the processing and compare byte for byte.",
    "epochs": "Decode a receiver log (NMEA 0183, u-blox NAV messages, gpsd JSON) into one row per epoch.",
    "integrity": "Check every epoch with every integrity source the log has and write the epoch table with its verdict.",
    "design": "Derive thresholds and probabilities (paper 001 eqs. 16–24; thesis eqs. 5.5, 5.10).",
    "simulate": "Simulate a drive with known truth: NMEA log, GSDC derived CSV, truth trajectory, driven geo-objects.",
    "locate": "The last trusted position of each vehicle (RAIM valid at --hal), and the last position of any kind when it differs.",
    "findings": "Tamper and evasion findings of one trip (gaps, jamming signs, spoofing signs), with times, positions and evidence.",
    "enforce": "Cross-check RFID/DSRC gantry reads with the GNSS trip: reads where the trip was elsewhere or silent, gantries "
               "passed without a read.",
    "plot": "Figures of a run (PNG, or -f svg|pdf): trajectory over the geo-objects by RAIM status; HPL/HAL and P_FA over "
            "time; valid independent positions per passage against N_Th; with --truth, the Stanford diagram.",
    "report": "One self-contained HTML page for auditing a trip: a Leaflet map (geo-objects, positions by status, charged "
              "segments), the invoice, findings and the per-epoch table. Opens offline.",
    "batch": "Charge many logs: one invoice and one epoch table per log, a Parquet dataset partitioned by date and vehicle, a summary.",
    "info": "What a file holds, before anything is charged on it.",
    "osnma": "Verify Galileo OSNMA (navigation message authentication) in a log.",
    "geoobjects": "Build, check and inspect geo-objects: constant-HAL buffers around tolled roads.",
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


def build_app(only: str | None = None, listing: bool = False) -> typer.Typer:
    """The application with every command, or with just ``only`` (what ``tollcli CMD`` needs: a fast start; "" none).

    ``listing``: every command as a stand-in that carries only its summary (:data:`SUMMARIES`) — what ``tollcli``
    and ``tollcli --help`` show without a command, in a fraction of the time; never run."""
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
    if listing:  # (typer lists a group after the commands)
        for name in sorted(COMMANDS, key=lambda n: n == "geoobjects"):
            app.command(name=name, help=SUMMARIES[name], epilog=EPILOG)(_stand_in)
        return app
    for name, (module, attr) in COMMANDS.items():
        if only is not None and name != only:
            continue
        command = getattr(importlib.import_module(module), attr)
        if name == "geoobjects":
            app.add_typer(command, name="geoobjects")
        else:
            app.command(epilog=EPILOG)(command)
    return app


def _stand_in() -> None:  # pragma: no cover - a listed command is built for real before it runs
    raise RuntimeError("a command of the listing was run")


def __getattr__(name: str):
    if name == "app":  # the whole application (tests, man pages, completion)
        return build_app()
    raise AttributeError(name)
