"""``tollcli plot`` and ``tollcli report``: figures and a self-contained HTML audit page of a run."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.cli.console import warn
from tollcli.errors import UsageError
from tollcli.io.writers import write_text_atomic

Run = Annotated[str, typer.Argument(metavar="RUN", help="An invoice written by 'tollcli process' (it names its log and geo-objects).", show_default=False)]
Truth = Annotated[Optional[str], typer.Option("--truth", help="Truth trajectory CSV (time_utc, lat_deg, lon_deg): adds errors and the Stanford diagram.")]


def plot(
    run: Run,
    output: Annotated[str, typer.Option("-o", "--output", help="Folder for the PNG figures (created if needed).")],
    truth: Truth = None,
    quiet: opt.Quiet = False,
) -> None:
    """PNG figures of a run: trajectory over the geo-objects by RAIM status; HPL/HAL and P_FA over time; valid independent positions per passage against N_Th; with --truth, the Stanford diagram."""
    from tollcli.report.plots import write_plots
    from tollcli.report.run_data import load_run

    paths = write_plots(load_run(run, truth), output)
    warn(f"{run}: " + ", ".join(paths), quiet)


def report(
    run: Run,
    output: Annotated[str, typer.Option("-o", "--output", help="The HTML file to write (- for stdout).")] = "report.html",
    truth: Truth = None,
    tiles: Annotated[Optional[str], typer.Option("--tiles", help="A tile URL template for a background map (the page then fetches tiles: no longer offline).")] = None,
    quiet: opt.Quiet = False,
) -> None:
    """One self-contained HTML page for auditing a trip: a Leaflet map (geo-objects, positions by status, charged segments), the invoice, findings and the per-epoch table. Opens offline."""
    from tollcli.report.html import report_html
    from tollcli.report.run_data import load_run

    if tiles is not None and "{z}" not in tiles:
        raise UsageError("--tiles: a URL template with {z}, {x} and {y}")
    write_text_atomic(output, report_html(load_run(run, truth), tiles))
    warn(f"{run}: report written to {output}", quiet)
