"""``tollcli batch``: one invoice and one epoch table per log, a combined Parquet dataset, a summary.

Layout of OUTDIR:

``invoices/<vehicle>/<log name>.json``   the invoice (as ``tollcli process`` writes it)
``epochs/date=<YYYY-MM-DD>/vehicle=<vehicle>/<log name>.parquet``  the log's epoch table with RAIM columns:
                                          together a Hive-partitioned dataset DuckDB or Spark read as one table:
                                          one schema for every input kind (``epoch_schema.py``)
``failed/<log name>.txt``                 why a log could not be processed
``summary.json``                          every log's outcome, totals per currency (sorted: the same bytes
                                          whatever the worker count or scheduler)

``<log name>`` is the file name without its log suffix (``truck1.day2.nmea`` → ``truck1.day2``); when two
logs would write the same files (``day1/TRK-042.nmea``, ``day2/TRK-042.nmea``), the one whose invoice is
already there (or the first by path) keeps the name and the others get ``<log name>~<8 hex digits of their
folder's path>``: every log has its own outputs, stable from run to run. Vehicle ids and names are data,
never paths: they are percent-encoded into one folder or file name (``../x`` → ``..%2Fx``).

A log is skipped (unless ``force``) only when its invoice exists and records the same log (path and
SHA-256), the same geo-object, tariff and road files (SHA-256), every setting and the tool version.

A vehicle's logs are one drive when they follow each other: when a log starts at most ``PASSAGE_GAP_S``
after the vehicle's previous log ended, a passage that log ended inside and this one starts inside is one
passage, charged once — by the invoice where it began; the next invoice lists its part at fee 0 (band
``continued``, naming the log it continues) and records that in its parameters, so ``verify`` reproduces it.
Logs of one vehicle whose periods overlap (the same drive uploaded twice, a clock gone wrong) are charged
each as it is, but never silently: each outcome lists the logs it overlaps and the summary counts them.
A log that fails in any way — bad data or an error of the tool — is reported in ``failed/`` and the
summary; it never stops the others.
Work runs on a local process pool (``workers``) or, with ``scheduler``, on an existing Dask
distributed cluster; each log's outputs depend only on that log and the shared settings.

Why this file is long: the pool's life cycle (its workers started so that each dies with the batch, reads on one
thread when the workers take every core, and is stopped at once on an interruption) belongs with the loop that
hands out the logs (where each log writes lives in ``batch_outputs.py``).
"""

from __future__ import annotations

import ctypes
import json
import os
import signal
import threading
import time
from dataclasses import asdict, dataclass, replace
from decimal import Decimal

import pandas as pd

from tollcli import __version__
from tollcli.charging.invoice import file_sha256, invoice_json
from tollcli.charging.recognition import PASSAGE_GAP_S
from tollcli.errors import DataError, SystemFailureError, UsageError
from tollcli.io.writers import TableWriter, output_folder, write_text_atomic
from tollcli.job.epoch_schema import conform_epochs, epoch_schema
from tollcli.job.fleet import read_fleet
from tollcli.job.batch_outputs import path_component, plan_outputs, vehicle_error
from tollcli.job.log_files import is_pseudorange_log
from tollcli.job.pipeline import ChargeSettings, charge_log


@dataclass(frozen=True)
class Job:
    log: str
    geo: str
    tariff: str
    settings: ChargeSettings
    outdir: str
    force: bool = False
    roads: str | None = None
    vehicle: str = ""  # the vehicle id (data, as the log or the options give it)
    name: str = ""  # the outputs' file name (a safe path component, unique in OUTDIR)
    input_sha256: tuple = ()  # (key, SHA-256) of the shared inputs, for the resume check
    nav: str | tuple[str, ...] | None = None  # the navigation file(s) shared by the logs (raw-measurement inputs)
    error: str = ""  # why the log cannot be charged before it is read (a vehicle the fleet file does not list)
    osnma_merkle: str | None = None  # the OSNMA Merkle tree for every log (None: each u-blox log's own, beside it)
    osnma_public_keys: tuple[str, ...] | None = None


def _current(done: dict, job: Job, settings: ChargeSettings, log_sha) -> bool:
    """Whether an earlier invoice was made from this very log, inputs, settings and tool version (``log_sha``: a
    function giving the log's SHA-256, called only when everything else agrees)."""
    inputs, parameters = done.get("inputs") or {}, done.get("parameters") or {}
    if not isinstance(inputs, dict) or not isinstance(parameters, dict) or done.get("tool") != f"tollcli {__version__}":
        return False
    if not isinstance(inputs.get("log"), str) or os.path.abspath(inputs["log"]) != os.path.abspath(job.log):
        return False
    if any(inputs.get(key) != sha for key, sha in job.input_sha256):
        return False
    # ``continued`` depends on the vehicle's other logs: join_passages checks it after every log is done
    recorded = {"input_format": "auto", "vehicle_attrs": None, "require_authenticated": False, **parameters}  # recorded only when given
    compared = asdict(settings)
    del compared["continued"]
    if "positioning" not in recorded:  # a navigation log's invoice (no positioning to choose), or an older invoice of a
        if is_pseudorange_log(job.log, settings.input_format):  # pseudorange log: made with snapshot positions
            recorded["positioning"] = "snapshot"
        else:
            del compared["positioning"]
    if not all(k in recorded and recorded[k] == v for k, v in compared.items()):
        return False
    return inputs.get("log_sha256") == log_sha()


def run_one(job: Job) -> dict:
    """Process one log into OUTDIR; never raises for a bad log (the outcome says what happened)."""
    if not job.name:  # a job made without plan_outputs
        vehicle, folder, name = plan_outputs([job.log], job.settings, job.outdir)[0]
    else:
        vehicle, folder, name = job.vehicle, path_component(job.vehicle), job.name
    inv_path = os.path.join(job.outdir, "invoices", folder, name + ".json")
    outcome = {"log": job.log, "vehicle": vehicle, "invoice": os.path.relpath(inv_path, job.outdir)}
    settings = replace(job.settings, vehicle=vehicle)
    if job.error:
        return _failed(job, name, outcome, job.error)
    if not job.force and os.path.isfile(inv_path):  # an earlier run's invoice: the log is hashed only to compare with it
        try:
            with open(inv_path, encoding="utf-8") as fh:
                done = json.load(fh)
            if isinstance(done, dict) and _current(done, job, settings, lambda: file_sha256(job.log)):
                return {**outcome, "status": "skipped", "total": done["total"], "currency": done["currency"],
                        "lines": len(done["lines"])}  # fmt: skip
        except (OSError, ValueError, KeyError, TypeError):
            pass  # a damaged earlier output: do it again
    try:
        return _process(job, settings, folder, name, inv_path, outcome)
    except (DataError, UsageError) as exc:
        return _failed(job, name, outcome, str(exc))
    except OSError as exc:  # the system refused a file (disk full, permissions): that log's failure, of the system's class
        return _failed(job, name, outcome, f"{job.log}: {system_message(exc)}", system=True)
    except Exception as exc:  # noqa: BLE001 - one log's failure, whatever it is, never stops the others
        return _failed(job, name, outcome, f"{job.log}: internal error ({type(exc).__name__}: {exc}); please report it")


def system_message(exc: OSError) -> str:
    """What the system refused, in one line: ``cannot write PATH (No space left on device)``."""
    what = f"cannot write {exc.filename}" if exc.filename else "a file could not be written or read"
    return f"{what} ({exc.strerror or exc})"


def _failed(job: Job, name: str, outcome: dict, message: str, system: bool = False) -> dict:
    """The log's failed outcome, its reason also in ``failed/NAME.txt`` when that can be written (a full disk, a
    ``failed`` folder that is a dangling link: the outcome says so instead). ``system_error``: the failure is the
    system's (exit 4), not the log's."""
    out = {**outcome, "status": "failed", "error": message}
    try:
        os.makedirs(os.path.join(job.outdir, "failed"), exist_ok=True)
        write_text_atomic(os.path.join(job.outdir, "failed", name + ".txt"), message + "\n")
    except OSError as exc:
        out["error"] = f"{message} (its note in failed/ could not be written: {exc.strerror or exc})"
        system = True
    if system:
        out["system_error"] = True
    return out


def _process(job: Job, settings: ChargeSettings, folder: str, name: str, inv_path: str, outcome: dict) -> dict:
    tables: list = []
    invoice, stats = charge_log(job.log, job.geo, job.tariff, settings, job.nav, roads=job.roads, epoch_table=tables,
                                geo_sha256=dict(job.input_sha256).get("geoobjects_sha256"),  # hashed once per batch
                                osnma_merkle=job.osnma_merkle,
                                osnma_public_keys=list(job.osnma_public_keys) if job.osnma_public_keys is not None else None)  # fmt: skip
    table = tables[0]
    dated = table["time_utc"].dropna()
    date = dated.iloc[0].strftime("%Y-%m-%d") if len(dated) else "unknown"
    ep_dir = os.path.join(job.outdir, "epochs", f"date={date}", f"vehicle={folder}")
    os.makedirs(ep_dir, exist_ok=True)
    with TableWriter(os.path.join(ep_dir, name + ".parquet"), "parquet", schema=epoch_schema()) as writer:
        writer.write(conform_epochs(table))  # one schema for every input kind; vehicle and date come from the path
        writer.commit()
    os.makedirs(os.path.dirname(inv_path), exist_ok=True)
    write_text_atomic(inv_path, invoice_json(invoice))  # last: its presence marks the log done
    failed = os.path.join(job.outdir, "failed", name + ".txt")
    if os.path.exists(failed):
        os.unlink(failed)
    return {**outcome, "status": "done", "total": invoice["total"], "currency": invoice["currency"], "lines": len(invoice["lines"]),
            "epochs": int(len(table)), "skipped_lines": int(stats.skipped) if stats is not None else 0}  # fmt: skip


def join_passages(outcomes: list[dict], jobs: dict[str, Job]) -> list[dict]:
    """Charge once a passage cut by the boundary between two consecutive logs of a vehicle.

    Every invoice whose recorded ``continued`` differs from what its vehicle's previous log gives is made
    again with it (rarely more than a few: only logs that start inside a geo-object the last one ended in).
    What a log carries over depends only on that log's lines, never on what it took in: one pass settles.
    """
    invoices = {}
    for o in outcomes:
        if o["status"] in ("done", "skipped"):
            try:
                with open(os.path.join(jobs[o["log"]].outdir, o["invoice"]), encoding="utf-8") as fh:
                    invoices[o["log"]] = json.load(fh)
            except (OSError, ValueError):
                continue
    by_vehicle: dict[str, list[str]] = {}
    for log, inv in invoices.items():
        if isinstance(inv.get("period"), dict) and inv.get("scheme") != "city":  # (a crossing is an instant: nothing to join)
            by_vehicle.setdefault(str(inv.get("vehicle")), []).append(log)
    wanted: dict[str, dict | None] = {log: None for log in invoices}
    overlaps: dict[str, set[str]] = {}
    for logs in by_vehicle.values():
        logs.sort(key=lambda log: (invoices[log]["period"]["start_utc"], log))
        for a, b in zip(logs, logs[1:]):
            wanted[b] = _carried_over(invoices[a], invoices[b]) or None
        for i, a in enumerate(logs):  # the same vehicle in two logs at once: the same drive twice, charged in each
            for b in logs[i + 1 :]:
                if invoices[b]["period"]["start_utc"] >= invoices[a]["period"]["end_utc"]:
                    break
                overlaps.setdefault(a, set()).add(b)
                overlaps.setdefault(b, set()).add(a)
    redo = {log for log, inv in invoices.items() if (inv.get("parameters") or {}).get("continued") != wanted[log]}
    out = []
    for o in outcomes:
        if o["log"] in redo:
            job = jobs[o["log"]]
            o = run_one(replace(job, settings=replace(job.settings, continued=wanted[o["log"]]), force=True))
        if o["log"] in overlaps and o["status"] != "failed":
            o = {**o, "overlaps": sorted(overlaps[o["log"]])}
        out.append(o)
    return out


def _carried_over(previous: dict, invoice: dict) -> dict:
    """The passages ``previous`` charged and ended inside, when ``invoice`` follows it within the passage gap."""
    end, start = pd.Timestamp(previous["period"]["end_utc"]), pd.Timestamp(invoice["period"]["start_utc"])
    if not 0 <= (start - end).total_seconds() <= PASSAGE_GAP_S:
        return {}
    log = (previous.get("inputs") or {}).get("log", "")
    carried: dict[str, dict] = {}
    for line in previous.get("lines", []):
        if (end - pd.Timestamp(line["exit_utc"])).total_seconds() <= PASSAGE_GAP_S:
            if line["geoobject"] not in carried or line["exit_utc"] > carried[line["geoobject"]]["exit_utc"]:
                carried[line["geoobject"]] = {"log": str(log), "exit_utc": line["exit_utc"]}
    return carried


def summarise(outcomes: list[dict]) -> dict:
    outcomes = sorted(outcomes, key=lambda o: o["log"])
    totals: dict[str, Decimal] = {}
    for o in outcomes:
        if o["status"] in ("done", "skipped"):
            totals[o["currency"]] = totals.get(o["currency"], Decimal(0)) + Decimal(o["total"])
    counts = {s: sum(o["status"] == s for o in outcomes) for s in ("done", "skipped", "failed")}
    overlapping = sum("overlaps" in o for o in outcomes)
    return {"logs": len(outcomes), **counts, "overlapping": overlapping, "totals": {k: str(v) for k, v in sorted(totals.items())},
            "outcomes": outcomes}  # fmt: skip


def _start_worker(parent_pid: int, one_thread: bool) -> None:
    """Pool worker initializer: :func:`die_with_parent`; with ``one_thread`` (the workers take every core) the
    worker reads its logs without reading ahead, unless ``TOLLCLI_READ_AHEAD`` says otherwise."""
    die_with_parent(parent_pid)
    if one_thread:
        from tollcli.io.prefetch import ENVIRONMENT

        os.environ.setdefault(ENVIRONMENT, "0")


def die_with_parent(parent_pid: int) -> None:
    """Pool worker initializer: the worker ends when the batch process ends, however it ends (even SIGKILL).

    Linux tells the worker at once (``PR_SET_PDEATHSIG``); elsewhere a thread notices within a second that
    its parent changed. Either way the worker gets SIGTERM and discards the output it was writing.
    """
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError, TypeError):
        pass

    def stop(signum, frame):
        # one unwinding: the parent's death sends SIGTERM twice (PR_SET_PDEATHSIG and the watcher below); a second
        # one arriving while the first unwinds would interrupt the discarding of a half-written output
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if not _IN_JOB:  # idle, waiting for a job: nothing to discard
            os._exit(128 + signum)
        # should the unwinding be swallowed (a handler runs between any two bytecodes, also inside a __del__ or a
        # weakref callback, whose exceptions Python ignores), the worker still ends: it never takes another log
        ender = threading.Timer(STOP_GRACE_S, os._exit, args=(128 + signum,))
        ender.daemon = True
        ender.start()
        raise SystemExit(128 + signum)  # unwind: the outputs being written are discarded; then _run_in_worker ends

    signal.signal(signal.SIGTERM, stop)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(1.0)
        os.kill(os.getpid(), signal.SIGTERM)

    if os.getppid() != parent_pid:  # the parent ended before the worker could ask to be told
        os.kill(os.getpid(), signal.SIGTERM)
    threading.Thread(target=watch, name="watch-parent", daemon=True).start()


#: how long a pool worker told to stop may take to discard what it was writing before it is ended, s
STOP_GRACE_S = 5.0
#: whether this pool worker is processing a log (its SIGTERM unwinds the outputs) or idle (it just ends)
_IN_JOB = False


def _run_in_worker(job: Job) -> dict:
    """``run_one`` in a pool worker: a worker told to stop unwinds its log's outputs, then ends (never takes another)."""
    global _IN_JOB
    _IN_JOB = True
    try:
        return run_one(job)
    except Exception as exc:  # noqa: BLE001 - run_one never raises for a log: a defect; the log fails, the pool lives
        return {"log": job.log, "vehicle": job.vehicle, "invoice": "", "status": "failed", "system_error": isinstance(exc, OSError),
                "error": f"{job.log}: " + (system_message(exc) if isinstance(exc, OSError) else
                                           f"internal error ({type(exc).__name__}: {exc}); please report it")}  # fmt: skip
    except BaseException:  # noqa: BLE001 - SIGTERM or an interrupt: what was written has been discarded on the way out
        os._exit(143)
    finally:
        _IN_JOB = False


def _fleet_jobs(jobs: list[Job], table: dict, fleet: str) -> list[Job]:
    """Each job with its vehicle's class and attributes from the fleet file (or the reason it cannot be charged)."""
    out = []
    for job in jobs:
        entry = table.get(job.vehicle)
        if entry is None:
            out.append(replace(job, error=f"{job.log}: vehicle {job.vehicle!r} is not in the fleet file {fleet} "
                                          f"(its class and attributes decide the fee)"))  # fmt: skip
        else:
            out.append(replace(job, settings=replace(job.settings, vehicle_class=entry[0], vehicle_attrs=entry[1])))
    return out


def check_shared_inputs(geo: str, tariff: str, settings: ChargeSettings, vehicles: dict | None = None) -> None:
    """What every log of a batch shares — geo-objects, tariff, settings — checked once, before any log: a typo in the
    tariff is one error (exit 1, or 2 for a file that is not there or a folder), not a failure of every log."""
    from tollcli.charging.city_tariff import is_city_tariff
    from tollcli.charging.recognition import load_geoobjects
    from tollcli.charging.tariffs import load_tariff
    from tollcli.job.pipeline import check_settings

    if is_city_tariff(tariff):
        from tollcli.job.city_days import check_city_inputs

        return check_city_inputs(geo, tariff, settings, vehicles is not None)
    tariff_doc = load_tariff(tariff)
    check_settings(settings, None if vehicles is not None else tariff_doc)  # (a fleet gives each vehicle its class)
    geo_objects = load_geoobjects(geo)
    tariff_doc.check_against(geo_objects.ids, geo_objects.road_class, geo)


def run_batch(logs: list[str], geo: str, tariff: str, settings: ChargeSettings, outdir: str, *, workers: int = 1,
              scheduler: str | None = None, force: bool = False, roads: str | None = None, nav: str | tuple[str, ...] | None = None,
              progress=None, fleet: str | None = None, osnma_merkle: str | None = None,
              osnma_public_keys: list[str] | None = None) -> dict:  # fmt: skip
    """Process every log; returns the summary (also written to OUTDIR/summary.json).

    ``fleet``: a fleet CSV (``fleet.py``) giving each vehicle its class and tariff attributes; a log of a vehicle
    it does not list fails (listed in failed/), it is never charged as some default vehicle.
    """
    vehicles = read_fleet(fleet) if fleet is not None else None  # a bad fleet file stops the batch before it starts
    check_shared_inputs(geo, tariff, settings, vehicles)  # so do the geo-objects, the tariff and the settings: once
    output_folder(outdir)
    shared = [("geoobjects_sha256", file_sha256(geo)), ("tariff_sha256", file_sha256(tariff))]
    if roads is not None:
        shared.append(("roads_sha256", file_sha256(roads)))
    if nav is not None:  # (several files: their digests in order, as the invoice lists them)
        shared.append(("nav_sha256", file_sha256(nav) if isinstance(nav, str) else [file_sha256(p) for p in nav]))
    if osnma_merkle is not None:
        shared.append(("osnma_merkle_sha256", file_sha256(osnma_merkle)))
    keys = tuple(osnma_public_keys) if osnma_public_keys is not None else None
    jobs = [Job(log, geo, tariff, settings, outdir, force, roads, vehicle, name, tuple(shared), nav,
                osnma_merkle=osnma_merkle, osnma_public_keys=keys, error=vehicle_error(log, vehicle))
            for log, (vehicle, _, name) in zip(logs, plan_outputs(logs, settings, outdir))]  # fmt: skip
    if vehicles is not None:
        jobs = _fleet_jobs(jobs, vehicles, fleet)
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

        # workers on every core: none reads ahead (a second thread per log would only cost CPU, ~10 %)
        one_thread = workers >= (os.cpu_count() or 1)
        pool = ProcessPoolExecutor(max_workers=workers, initializer=_start_worker, initargs=(os.getpid(), one_thread))
        try:
            for fut in done_first([pool.submit(_run_in_worker, job) for job in jobs]):
                outcomes.append(fut.result())
                tick(1)
        except BaseException:  # interrupted or terminated: stop the workers now, not after every queued log
            for process in list((getattr(pool, "_processes", None) or {}).values()):
                process.terminate()  # SIGTERM: a worker unwinds and discards what it was writing
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()
    outcomes = join_passages(outcomes, {job.log: job for job in jobs})
    summary = summarise(outcomes)
    from tollcli.job.city_days import settle_city_days

    settle_city_days(summary, outcomes, outdir, tariff)  # a city tariff: a vehicle's day is one day whatever its logs
    where = os.path.join(outdir, "summary.json")
    try:
        write_text_atomic(where, json.dumps(summary, indent=1, sort_keys=True) + "\n")
    except OSError as exc:  # a full disk at the very end: say what is missing and what is there
        raise SystemFailureError(f"{where}: the batch summary could not be written ({exc.strerror or exc}); {summary['done']} of "
                                 f"{summary['logs']} logs done, each of their invoices complete") from None  # fmt: skip
    return summary
