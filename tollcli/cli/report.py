"""``tollcli plot`` and ``tollcli report``: figures and a self-contained HTML audit page of a run."""

from __future__ import annotations

import json
from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note
from tollcli.errors import UsageError
from tollcli.io.writers import write_text_atomic

Run = Annotated[str, typer.Argument(metavar="RUN", help="An invoice written by 'tollcli process' (it names its log and geo-objects).", show_default=False)]
Truth = Annotated[Optional[str], typer.Option("--truth", help="Truth trajectory CSV (time_utc, lat_deg, lon_deg): adds errors and the Stanford diagram.")]


def plot(
    run: Run,
    output: Annotated[str, typer.Option("-o", "--output", help="Folder for the figures (created if needed).")],
    out_fmt: opt.out_format("png, svg or pdf", "png") = None,
    truth: Truth = None,
    quiet: opt.Quiet = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the figures written as JSON on stdout.")] = False,
) -> None:
    """Figures of a run (PNG, or -f svg|pdf): trajectory over the geo-objects by RAIM status; HPL/HAL and P_FA over time; valid independent positions per passage against N_Th; with --truth, the Stanford diagram."""
    from tollcli.report.plots import PLOT_FORMATS, write_plots
    from tollcli.report.run_data import load_run

    fmt = (out_fmt or "png").lower()
    if fmt not in PLOT_FORMATS:
        raise UsageError(f"-f {out_fmt}: figures are png, svg or pdf")
    paths = write_plots(load_run(run, truth), output, fmt)
    if as_json:
        typer.echo(json.dumps({"run": run, "output": output, "format": fmt, "figures": paths}, sort_keys=True))
    else:
        note(f"{run}: " + ", ".join(paths), quiet)


def report(
    run: Run,
    output: Annotated[str, typer.Option("-o", "--output", help="The HTML file to write (- for stdout).")] = "report.html",
    out_fmt: opt.out_format("html", "html") = None,
    truth: Truth = None,
    tiles: Annotated[Optional[str], typer.Option("--tiles", help="A tile URL template for a background map (the page then fetches tiles: no longer offline).")] = None,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
) -> None:
    """One self-contained HTML page for auditing a trip: a Leaflet map (geo-objects, positions by status, charged segments), the invoice, findings and the per-epoch table. Opens offline."""
    from tollcli.report.html import report_html
    from tollcli.report.run_data import load_run

    if tiles is not None and "{z}" not in tiles:
        raise UsageError("--tiles: a URL template with {z}, {x} and {y}")
    if out_fmt is not None and out_fmt.lower() != "html":
        raise UsageError(f"-f {out_fmt}: the report is one HTML page (figures: 'tollcli plot -f png|svg|pdf')")
    if as_json and output == "-":
        raise UsageError("--json prints the summary on stdout: give the page a file with -o")
    data = load_run(run, truth)
    write_text_atomic(output, report_html(data, tiles))
    if as_json:
        typer.echo(json.dumps({"run": run, "output": output, "epochs": int(len(data.epochs)), "truth": truth,
                               "tiles": tiles}, sort_keys=True))
    else:
        note(f"{run}: report written to {output}", quiet)
