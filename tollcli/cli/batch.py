"""``tollcli batch``: many logs → invoices, epoch tables, a partitioned dataset and a summary."""

from __future__ import annotations

import json
import os
from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.cli.charge_options import ChargeOptions, charge_options
from tollcli.cli.console import note, progress
from tollcli.cli.settings_file import Config
from tollcli.errors import DataError, PartialError, SomeFailedError, SystemFailureError, UsageError
from tollcli.job.batch import run_batch
from tollcli.job.log_files import expand_inputs


@charge_options
def batch(
    inputs: Annotated[list[str], typer.Argument(metavar="INPUTS...", help="Logs: paths, globs, folders, or @FILE listing one path per line.", show_default=False)],
    output: Annotated[str, typer.Option("-o", "--output", help="Output folder (invoices/, epochs/, failed/, summary.json).")],
    workers: Annotated[int, typer.Option("--workers", help="Local worker processes (default: the CPU count).", min=1)] = max(os.cpu_count() or 1, 1),
    scheduler: Annotated[Optional[str], typer.Option("--scheduler", help="Address of a Dask distributed scheduler to run on instead (tcp://host:8786).")] = None,
    force: Annotated[bool, typer.Option("--force", help="Process logs again even when their invoice is up to date.")] = False,
    vehicle: Annotated[Optional[str], typer.Option("--vehicle", help="Vehicle id of every log (a vehicle's logs of a day; default: each log's own, else its file name).")] = None,
    fleet: Annotated[Optional[str], typer.Option("--fleet", help="Fleet CSV: vehicle,vehicle_class,<attribute>… per vehicle id; each log is charged as its vehicle (one not listed fails).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON on stdout.")] = False,
    quiet: opt.Quiet = False,
    fmt: Annotated[Optional[str], typer.Option("--format", hidden=True)] = None,
    config: Config = None,
    *,
    charge: ChargeOptions,
) -> None:
    """Charge many logs: one invoice and one epoch table per log, a Parquet dataset partitioned by date and vehicle, a summary.

    Resumable: a log whose invoice records its current SHA-256 is skipped (--force
    redoes it). A bad log is reported in failed/ and the summary and never stops
    the others (exit 6 when some failed, 1 when all did, 4 when the system refused their files). Outputs do not depend on
    the worker count or the scheduler. A vehicle's consecutive logs (the next
    starting within 120 s of the last) are one drive: a passage cut by the file
    boundary is charged once, where it began; the next invoice lists its part at
    fee 0 (band 'continued'). Ending the batch (even kill -9) ends its workers.
    A mixed fleet: --fleet FILE.csv gives each vehicle id its class and per-km
    tariff attributes (docs/tariffs.md).
    """
    if fleet is not None and charge.vehicle_attr:
        raise UsageError("--fleet gives every vehicle its attributes: leave out --vehicle-attr")
    _, input_format = opt.split_format(fmt, charge.input_format)  # --format: the input's, as before --input-format
    passed_over: list[str] = []
    logs = expand_inputs(inputs, passed_over)
    if passed_over:
        note(f"  passed over {len(passed_over)} files that are not receiver logs: {', '.join(passed_over[:5])}"
             + (" …" if len(passed_over) > 5 else ""), quiet)  # fmt: skip
    settings = charge.settings(vehicle, input_format)
    with progress(f"batch of {len(logs)} logs", quiet, total=len(logs), unit="logs") as advance:
        summary = run_batch(logs, charge.geo, charge.tariff, settings, output, workers=workers, scheduler=scheduler, force=force,
                            roads=charge.roads, nav=charge.nav, progress=advance, fleet=fleet, osnma_merkle=charge.osnma_merkle,
                            osnma_public_keys=charge.osnma_public_key)  # fmt: skip
    line = (f"{output}: {summary['logs']} logs: {summary['done']} done, {summary['skipped']} up to date, {summary['failed']} failed; "
            + ", ".join(f"{v} {k}" for k, v in summary["totals"].items()))  # fmt: skip
    if as_json:
        typer.echo(json.dumps({k: v for k, v in summary.items() if k != "outcomes"}, sort_keys=True))
    note(line, quiet)
    if summary["overlapping"]:
        note(f"  warning: {summary['overlapping']} logs overlap in time another log of the same vehicle (each is charged: "
             f"the same drive twice?); their outcomes in {os.path.join(output, 'summary.json')} name the others", quiet)  # fmt: skip
    for o in summary["outcomes"]:
        if o["status"] == "failed":
            note(f"  failed: {o['error']}", quiet)
    if summary["failed"]:  # one line even with --quiet: an exit code ≠ 0 always says why
        first = next(o["error"] for o in summary["outcomes"] if o["status"] == "failed")
        message = (f"{summary['failed']} of {summary['logs']} logs failed (see {os.path.join(output, 'failed')}); "
                   f"first: {first}")  # fmt: skip
        if any(o.get("system_error") for o in summary["outcomes"]):  # the system's failure (disk full): exit 4
            first = next(o["error"] for o in summary["outcomes"] if o.get("system_error"))
            raise SystemFailureError(f"{summary['failed']} of {summary['logs']} logs failed, the system refusing a file; first: {first}")
        raise (DataError if summary["failed"] == summary["logs"] else SomeFailedError)(message)
    over = [o for o in summary["outcomes"] if charge.max_bad is not None and o.get("skipped_lines", 0) > charge.max_bad]
    if over:
        raise PartialError(f"{len(over)} logs skipped more lines than --max-bad {charge.max_bad} (first: {over[0]['log']}, "
                           f"{over[0]['skipped_lines']} lines); outputs were written")
