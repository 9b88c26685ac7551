"""``tollcli batch``: one invoice and one epoch table per log, a combined Parquet dataset, a summary.

Layout of OUTDIR:

``invoices/<vehicle>/<log name>.json``   the invoice (as ``tollcli process`` writes it)
``epochs/date=<YYYY-MM-DD>/vehicle=<vehicle>/<log name>.parquet``  the log's epoch table with RAIM columns:
                                          together a Hive-partitioned dataset DuckDB or Spark read as one table
``failed/<log name>.txt``                 why a log could not be processed
``summary.json``                          every log's outcome, totals per currency (sorted: the same bytes
                                          whatever the worker count or scheduler)

A log whose invoice exists and records the log's current SHA-256 is skipped unless ``force``.
Work runs on a local process pool (``workers``) or, with ``scheduler``, on an existing Dask
distributed cluster; each log's outputs depend only on that log and the shared settings.
"""

from __future__ import annotations

import glob
import json
import os
from dataclasses import asdict, dataclass
from decimal import Decimal

from tollcli.charging.invoice import file_sha256, invoice_json
from tollcli.enforcement.locate import vehicle_from_log, vehicle_from_path
from tollcli.errors import DataError, UsageError
from tollcli.io.writers import TableWriter, write_text_atomic
from tollcli.job.pipeline import ChargeSettings, charge_log

LOG_SUFFIXES = (".nmea", ".nmea.gz", ".log", ".log.gz", ".txt", ".gz", ".csv")


@dataclass(frozen=True)
class Job:
    log: str
    geo: str
    tariff: str
    settings: ChargeSettings
    outdir: str
    force: bool = False
    roads: str | None = None


def expand_inputs(inputs: list[str]) -> list[str]:
    """Logs from paths, globs, directories (their log files) and list files (``@list.txt``: one path per line)."""
    found: list[str] = []
    for item in inputs:
        if item.startswith("@"):
            try:
                with open(item[1:], encoding="utf-8") as fh:
                    found += [ln.strip() for ln in fh if ln.strip() and not ln.startswith("#")]
            except OSError as exc:
                raise UsageError(f"{item[1:]}: cannot read the list of logs ({exc.strerror})") from None
        elif os.path.isdir(item):
            found += [p for p in glob.glob(os.path.join(item, "**", "*"), recursive=True)
                      if os.path.isfile(p) and p.lower().endswith(LOG_SUFFIXES)]  # fmt: skip
        elif any(ch in item for ch in "*?["):
            found += [p for p in glob.glob(item, recursive=True) if os.path.isfile(p)]
        else:
            found.append(item)
    logs = sorted(dict.fromkeys(os.path.normpath(p) for p in found))
    if not logs:
        raise UsageError("no logs found in " + " ".join(inputs))
    return logs


def _name(log: str) -> str:
    return vehicle_from_path(log)


def run_one(job: Job) -> dict:
    """Process one log into OUTDIR; never raises for a bad log (the outcome says what happened)."""
    vehicle = job.settings.vehicle or vehicle_from_log(job.log) or vehicle_from_path(job.log)
    name = _name(job.log)
    inv_path = os.path.join(job.outdir, "invoices", vehicle, name + ".json")
    outcome = {"log": job.log, "vehicle": vehicle, "invoice": os.path.relpath(inv_path, job.outdir)}
    try:
        log_sha = file_sha256(job.log)
    except OSError as exc:
        return {**outcome, "status": "failed", "error": f"{job.log}: {exc.strerror}"}
    if not job.force and os.path.isfile(inv_path):
        try:
            with open(inv_path, encoding="utf-8") as fh:
                done = json.load(fh)
            if done.get("inputs", {}).get("log_sha256") == log_sha:
                return {**outcome, "status": "skipped", "total": done["total"], "currency": done["currency"],
                        "lines": len(done["lines"])}  # fmt: skip
        except (OSError, ValueError):
            pass  # a damaged earlier output: do it again
    settings = ChargeSettings(**{**asdict(job.settings), "vehicle": vehicle})
    tables: list = []
    try:
        invoice, stats = charge_log(job.log, job.geo, job.tariff, settings, roads=job.roads, epoch_table=tables)
    except (DataError, UsageError) as exc:
        message = str(exc)
        os.makedirs(os.path.join(job.outdir, "failed"), exist_ok=True)
        write_text_atomic(os.path.join(job.outdir, "failed", name + ".txt"), message + "\n")
        return {**outcome, "status": "failed", "error": message}
    table = tables[0]
    dated = table["time_utc"].dropna()
    date = dated.iloc[0].strftime("%Y-%m-%d") if len(dated) else "unknown"
    ep_dir = os.path.join(job.outdir, "epochs", f"date={date}", f"vehicle={vehicle}")
    os.makedirs(ep_dir, exist_ok=True)
    with TableWriter(os.path.join(ep_dir, name + ".parquet"), "parquet") as writer:
        writer.write(table)  # vehicle and date come from the partition path (a column too would clash with it)
        writer.commit()
    os.makedirs(os.path.dirname(inv_path), exist_ok=True)
    write_text_atomic(inv_path, invoice_json(invoice))  # last: its presence marks the log done
    failed = os.path.join(job.outdir, "failed", name + ".txt")
    if os.path.exists(failed):
        os.unlink(failed)
    return {**outcome, "status": "done", "total": invoice["total"], "currency": invoice["currency"], "lines": len(invoice["lines"]),
            "epochs": int(len(table)), "skipped_lines": int(stats.skipped) if stats is not None else 0}  # fmt: skip


def summarise(outcomes: list[dict]) -> dict:
    outcomes = sorted(outcomes, key=lambda o: o["log"])
    totals: dict[str, Decimal] = {}
    for o in outcomes:
        if o["status"] in ("done", "skipped"):
            totals[o["currency"]] = totals.get(o["currency"], Decimal(0)) + Decimal(o["total"])
    counts = {s: sum(o["status"] == s for o in outcomes) for s in ("done", "skipped", "failed")}
    return {"logs": len(outcomes), **counts, "totals": {k: str(v) for k, v in sorted(totals.items())}, "outcomes": outcomes}


def run_batch(logs: list[str], geo: str, tariff: str, settings: ChargeSettings, outdir: str, *, workers: int = 1,
              scheduler: str | None = None, force: bool = False, roads: str | None = None, progress=None) -> dict:  # fmt: skip
    """Process every log; returns the summary (also written to OUTDIR/summary.json)."""
    os.makedirs(outdir, exist_ok=True)
    jobs = [Job(log, geo, tariff, settings, outdir, force, roads) for log in logs]
    outcomes: list[dict] = []
    tick = progress or (lambda n: None)
    if scheduler:
        from distributed import Client, as_completed

        with Client(scheduler) as client:
            futures = client.map(run_one, jobs, pure=False)
            for fut in as_completed(futures):
                outcomes.append(fut.result())
                tick(1)
    elif workers <= 1:
        for job in jobs:
            outcomes.append(run_one(job))
            tick(1)
    else:
        from concurrent.futures import ProcessPoolExecutor
        from concurrent.futures import as_completed as done_first

        with ProcessPoolExecutor(max_workers=workers) as pool:
            for fut in done_first([pool.submit(run_one, job) for job in jobs]):
                outcomes.append(fut.result())
                tick(1)
    summary = summarise(outcomes)
    write_text_atomic(os.path.join(outdir, "summary.json"), json.dumps(summary, indent=1, sort_keys=True) + "\n")
    return summary
