"""Option definitions shared by the commands (one place, as in rasterio's rio)."""

from __future__ import annotations

import datetime as _dt
from typing import Annotated, Optional

import typer

LogArg = Annotated[
    str,
    typer.Argument(metavar="LOG", help="Receiver log: a path, a .gz path, or - for stdin.", show_default=False),
]
Output = Annotated[
    str,
    typer.Option("-o", "--output", help="Output file; the format follows the extension (.csv, .parquet, .geojson, .json); - is stdout (CSV)."),
]
Strict = Annotated[
    bool,
    typer.Option("--strict", help="Stop at the first unusable line (bad checksum, malformed, not NMEA) with its line number."),
]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress and no summary on stderr.")]
JsonSummary = Annotated[
    bool,
    typer.Option("--json", help="Print a machine-readable summary as JSON on stdout (needs -o FILE)."),
]
DateOpt = Annotated[
    Optional[_dt.datetime],
    typer.Option("--date", formats=["%Y-%m-%d"], help="UTC date of the first epoch, for logs without RMC/ZDA dates (YYYY-MM-DD)."),
]
