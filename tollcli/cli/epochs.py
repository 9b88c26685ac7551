"""``tollcli epochs``: a receiver log → the epoch table (and the satellite table)."""

from __future__ import annotations

import json
from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note, progress
from tollcli.errors import UsageError
from tollcli.io.log_run import LogRun
from tollcli.io.prefetch import read_ahead
from tollcli.io.writers import TableWriter, format_for
from tollcli.readers.navigation import iter_epoch_tables
from tollcli.readers.nmea import ReadStats
from tollcli.readers.nmea.reader import check_partial, check_usable


def epochs(
    log: opt.LogArg,
    output: opt.Output = "-",
    out_fmt: opt.TableFormat = None,
    satellites: Annotated[
        Optional[str],
        typer.Option("--satellites", help="Also write the satellite table (one row per satellite and epoch) here (its format: its extension, else -f)."),
    ] = None,
    strict: opt.Strict = False,
    date: opt.DateOpt = None,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
    max_bad: opt.MaxBad = None,
    reader: Annotated[
        str,
        typer.Option("--reader", help="bulk (array decoding, the default) or reference (one line at a time: "
                     "slower, the same tables; for cross-checking a log)."),  # fmt: skip
    ] = "bulk",
) -> None:
    """Decode a receiver log (NMEA 0183, u-blox NAV messages, gpsd JSON) into one row per epoch.

    Columns carry their units (lat_deg, alt_m, speed_mps, ...). Lines that
    cannot be used are skipped and counted on stderr; --strict makes the first
    one an error.
    """
    if reader not in ("bulk", "reference"):
        raise UsageError(f"--reader {reader}: bulk or reference")
    if as_json and output == "-":
        raise UsageError("--json prints the summary on stdout: give the table a file with -o")
    if satellites == "-" and output == "-":
        raise UsageError("only one table can go to stdout: give --satellites or -o a file")
    stats = ReadStats()
    epoch_writer = TableWriter(output, format_for(output, fmt=out_fmt))
    sat_writer = TableWriter(satellites, _sat_format(satellites, out_fmt)) if satellites else None
    with epoch_writer, (sat_writer or _Null()):
        with progress(f"reading {log}", quiet, log=log) as advance, LogRun(log, hashed=False) as run:  # the log opened once, not hashed: no invoice names it
            tables = iter_epoch_tables(run, strict=strict, date=date.date() if date else None, stats=stats, engine=reader)
            with read_ahead(tables) as chunks:  # the next chunk read while this one is written
                for chunk in chunks:
                    epochs = chunk.epoch_columns
                    epoch_writer.write(epochs)
                    if sat_writer is not None:
                        sat_writer.write(chunk.satellite_columns)
                    advance(len(epochs), int(epochs["line"].max()) if len(epochs) else None)
        check_usable(stats)
        if stats.epochs == 0:
            from tollcli.readers.nmea.tables import epoch_columns, satellite_columns

            epoch_writer.write(epoch_columns(None))
            if sat_writer is not None:
                sat_writer.write(satellite_columns(None, None))
        epoch_writer.commit()
        if sat_writer is not None:
            sat_writer.commit()
    if as_json:
        typer.echo(json.dumps(stats.as_dict(), sort_keys=True))
    else:
        note(stats.summary(), quiet)
    check_partial(stats, max_bad)


def _sat_format(path: str, fmt: str | None) -> str:
    """The satellite table's format: its own extension, else -f, else CSV."""
    try:
        return format_for(path)
    except UsageError:
        if fmt:
            return format_for(path, fmt=fmt)
        raise


class _Null:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None
