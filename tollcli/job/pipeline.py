"""The whole charging job as one function: log + geo-objects + tariff → invoice (used by process and verify).

Why this file is long: it is the one place every input kind meets the charge — the settings and their checks, the
navigation and pseudorange chunk sources (with the fallback to a u-blox receiver's own fixes), the chunk loop and
what the invoice records of how the log was read; the log's clock (``log_clock.py``) and what the receiver's outputs
were not (``receiver_notes.py``) live beside it.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import math
import os
from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd

from tollcli.charging.invoice import (
    build_invoice,
    content_sha256,  # noqa: F401  (verify and the tests take it from here too)
    explain_not_charged,
    file_sha256,
    seal,
)
from tollcli.charging.nothing_seen import TrackExtent
from tollcli.charging.rate_tables import check_vehicle
from tollcli.charging.recognition import inside_pairs, load_geoobjects, warm_up
from tollcli.charging.tariffs import load_tariff
from tollcli.enforcement.findings import FindingSettings
from tollcli.enforcement.trip import cn0_summary
from tollcli.errors import DataError, UsageError
from tollcli.gnss.measurements import Measurements
from tollcli.gnss.nmea_measurements import AngleCarry, nmea_measurements
from tollcli.gnss.pseudorange_inputs import NoOrbitsError
from tollcli.gnss.sigma_models import NominalModel
from tollcli.gnss.wls import Geometry, wls_geometry
from tollcli.integrity.environment import ENVIRONMENTS, EnvironmentCarry
from tollcli.integrity.nav_authentication import epoch_authentication, not_checked
from tollcli.integrity.raim import MODES, RaimParams
from tollcli.integrity.run import hal_free_terms, level_name, model_hpl, model_level_read, run_raim, settle_sources
from tollcli.integrity.sources import LEVEL_CHOICES, LEVELS
from tollcli.integrity.trajectory import POSITIONINGS
from tollcli.io.sources import BLOCK_BYTES as SOURCE_BLOCK_BYTES
from tollcli.io.sources import INPUT_KINDS, printable_path
from tollcli.job.log_integrity import measured_environment
from tollcli.job.pseudorange_segments import placed_log as placed_pseudorange_log
from tollcli.job.osnma_evidence import OsnmaEvidence, failure_findings, fixes_before, osnma_evidence, record_in_invoice
from tollcli.job.osnma_evidence import inputs_record as osnma_inputs
from tollcli.io.columns import Columns
from tollcli.io.log_run import LogRun
from tollcli.job.streaming import TailCharger
from tollcli.job.file_info import solutions_instead
from tollcli.job.log_clock import RELATIVE_CLOCK_KINDS, check_given_date, check_not_future, on_the_clock, start_time_utc
from tollcli.job.receiver_notes import GPSD_DROPPED, count_ignored, receiver_notes
from tollcli.io.prefetch import read_ahead
from tollcli.readers.navigation import NAVIGATION_KINDS, iter_navigation_tables
from tollcli.readers.nmea import ReadStats
from tollcli.readers.nmea.reader import check_usable


@dataclass
class ChargeSettings:
    """Everything besides the input files that decides an invoice (recorded in it, for ``verify``)."""

    vehicle_class: str = "car"
    vehicle: str | None = None
    raim: str = "ss"
    p_md: float = 5e-5
    p_fa: float = 5e-3
    fde: bool = False
    sigma_model: str = "nominal"
    sigma_m: float = 5.0
    #: the error model's environment: auto (each epoch's from its residuals), open (nominal) or urban
    environment: str = "auto"
    p_sat: float = 1e-5  # ss: prior of a satellite fault
    p_const: float = 1e-8  # ss: prior of a constellation-wide fault
    tc_s: float = 5.0
    n_th: int = 1
    strict: bool = False
    date: str | None = None  # YYYY-MM-DD for logs without dates
    #: when a log whose times are seconds from its start (libRSF) began: ISO 8601 in UTC (``--start-time``)
    start_time: str | None = None
    policy: str | None = None  # which checks a position must pass (None: the strictest the inputs support)
    #: which integrity sources may validate a position (integrity.sources.LEVELS; "auto": the strictest the log supports)
    integrity_sources: str = "auto"
    #: passages the vehicle's previous log charged and ended inside (geo-object id → {"log", "exit_utc"}):
    #: set by ``batch`` so that a passage cut by a file boundary is charged once (see build_invoice)
    continued: dict | None = None
    #: the log's format (io.sources.sniff_format's kinds; "auto": recognised from the file)
    input_format: str = "auto"
    #: the vehicle's attributes for a tariff of per-km tables (attribute → value, e.g. euro_class → euro6); None: none
    vehicle_attrs: dict | None = None
    #: a position counts only when its navigation data were authenticated (Galileo OSNMA,
    #: integrity.nav_authentication.ACCEPTED): ``--require-authenticated``
    require_authenticated: bool = False
    #: where a pseudorange log's positions come from (integrity.trajectory.POSITIONINGS): smoothed (forward and
    #: backward over the whole log), filtered (forward only), snapshot (each epoch alone, the RAIM's) or auto (smoothed
    #: where the log can carry a trajectory); recorded for pseudorange logs only (a navigation log's positions are its
    #: receiver's)
    positioning: str = "auto"


#: the shortest correlation time accepted, s (a 10 Hz receiver's epoch interval)
MIN_TC_S = 0.1


def check_settings(settings: ChargeSettings, tariff=None) -> None:
    """UsageError for settings the CLI would refuse, wherever they come from (options, an invoice to verify, batch)."""
    def bad(name: str, value, rule: str):
        raise UsageError(f"{name} = {value!r}: {rule}")

    number = (int, float)
    if not isinstance(settings.tc_s, number) or not math.isfinite(settings.tc_s) or settings.tc_s < MIN_TC_S:
        bad("tc_s (--tc)", settings.tc_s, f"the correlation time must be a number ≥ {MIN_TC_S} s")
    if not isinstance(settings.n_th, int) or isinstance(settings.n_th, bool) or settings.n_th < 1:
        bad("n_th (--n-th)", settings.n_th, "the threshold must be a whole number ≥ 1")
    for name in ("p_md", "p_fa", "p_sat", "p_const"):
        value = getattr(settings, name)
        if not isinstance(value, number) or not 0 < value < 1:
            bad(f"{name} (--{name.replace('_', '-')})", value, "a probability strictly between 0 and 1")
    if settings.raim not in MODES:
        bad("raim (--raim)", settings.raim, f"one of {', '.join(MODES)}")
    if settings.environment not in ENVIRONMENTS:
        bad("environment (--environment)", settings.environment, f"one of {', '.join(ENVIRONMENTS)}")
    if not isinstance(settings.sigma_m, number) or not math.isfinite(settings.sigma_m) or settings.sigma_m <= 0:
        bad("sigma_m (--sigma)", settings.sigma_m, "a standard deviation > 0 m")
    if settings.positioning not in POSITIONINGS:
        bad("positioning (--positioning)", settings.positioning, f"one of {', '.join(POSITIONINGS)}")
    if settings.integrity_sources not in LEVEL_CHOICES:
        bad("integrity_sources (--integrity-sources)", settings.integrity_sources, f"one of {', '.join(LEVEL_CHOICES)}")
    if not isinstance(settings.vehicle_class, str) or not settings.vehicle_class:
        bad("vehicle_class (--vehicle-class)", settings.vehicle_class, "a vehicle class of the tariff")
    if settings.continued is not None:
        _check_continued(settings.continued)
    if settings.input_format not in INPUT_KINDS:
        bad("input_format (--format)", settings.input_format, f"one of {', '.join(INPUT_KINDS)}")
    attrs = settings.vehicle_attrs
    if attrs is not None and (not isinstance(attrs, dict) or not all(isinstance(k, str) and isinstance(v, str) and k and v
                                                                        for k, v in attrs.items())):  # fmt: skip
        bad("vehicle_attrs (--vehicle-attr)", attrs, "a table of attribute → value, both texts")
    for name in ("require_authenticated", "fde", "strict"):
        if not isinstance(getattr(settings, name), bool):  # ("yes" is not true: a settings value is typed)
            bad(f"{name} (--{name.replace('_', '-')})", getattr(settings, name), "true or false")
    if settings.date is not None and not _is_date(settings.date):
        bad("date (--date)", settings.date, "a date YYYY-MM-DD")
    if settings.start_time is not None and start_time_utc(settings.start_time) is None:
        bad("start_time (--start-time)", settings.start_time, "a date and time with its UTC offset (2019-06-01T08:00:00Z)")
    for name in ("vehicle", "policy"):
        if getattr(settings, name) is not None and not isinstance(getattr(settings, name), str):
            bad(f"{name} (--{name})", getattr(settings, name), "a text")
    if not isinstance(settings.sigma_model, str):
        bad("sigma_model (--sigma-model)", settings.sigma_model, "a text")
    if attrs and "vehicle_class" in attrs:
        bad("vehicle_attrs (--vehicle-attr)", attrs, "the vehicle class is given by --vehicle-class")
    if tariff is not None:
        classes = tariff.vehicle_classes()
        if (classes or not tariff.tables) and settings.vehicle_class not in classes:
            bad("vehicle_class (--vehicle-class)", settings.vehicle_class,
                f"not a vehicle class of the tariff {tariff.source} ({', '.join(classes)})")
        if attrs and not tariff.tables:
            bad("vehicle_attrs (--vehicle-attr)", attrs, f"the tariff {tariff.source} has flat fees, no vehicle attributes")
        why = check_vehicle(attrs or {}, tariff.vehicle, tariff.source) if tariff.tables else ""
        if why:
            bad("vehicle_attrs (--vehicle-attr)", attrs, why)


def _is_date(value) -> bool:
    """Whether ``value`` is a date written YYYY-MM-DD (as ``--date`` takes it, and an invoice records it)."""
    import datetime as dt

    if not isinstance(value, str) or len(value) != 10:
        return False
    try:
        dt.date.fromisoformat(value)
    except ValueError:
        return False
    return True


def _check_continued(continued) -> None:
    rule = "a table of geo-object id → {log, exit_utc} (the passages a previous log ended inside)"
    if not isinstance(continued, dict):
        raise UsageError(f"continued = {continued!r}: {rule}")
    for gid, carried in continued.items():
        if not isinstance(carried, dict) or set(carried) != {"log", "exit_utc"} or not all(isinstance(v, str) for v in carried.values()):
            raise UsageError(f"continued[{gid!r}] = {carried!r}: {rule}")
        try:
            pd.Timestamp(carried["exit_utc"]).tz_convert("UTC")
        except (ValueError, TypeError):
            raise UsageError(f"continued[{gid!r}].exit_utc = {carried['exit_utc']!r}: not a UTC time") from None


def charge_log(log: str, geo: str, tariff: str, settings: ChargeSettings, nav: str | tuple[str, ...] | None = None,
               roads: str | None = None, epoch_table: list | None = None,
               as_recorded: dict[str, str] | None = None, geo_sha256: str | None = None,
               osnma_merkle: str | None = None, osnma_public_keys: list[str] | None = None,
               osnma_auto: bool = True) -> tuple[dict, ReadStats | None]:  # fmt: skip
    """The invoice for one log (with its content hash) and the reader's statistics (NMEA).

    OSNMA (:mod:`tollcli.job.osnma_evidence`): the Merkle tree ``osnma_merkle`` and public keys
    ``osnma_public_keys`` when given, else (``osnma_auto``) those beside a u-blox log; with them each position
    records whether its navigation data were authenticated, and each failure becomes a finding.

    ``epoch_table``: a list that receives the per-epoch table (epochs + RAIM columns) for batch outputs.
    ``as_recorded``: the input paths to record instead of the ones read (``verify`` reads an invoice's
    inputs where it finds them and records them as the invoice names them). ``geo_sha256``: the geo-object file's
    SHA-256 when the caller has it (a batch hashes it once for all its logs).
    """
    from tollcli.charging.city_tariff import is_city_tariff

    if is_city_tariff(tariff):  # gantries and zones, the city's rules: job/city_charge.py
        from tollcli.job.city_charge import charge_city_log

        return charge_city_log(log, geo, tariff, settings, nav, epoch_table, as_recorded,
                               reading={"check_settings": check_settings, "navigation": _navigation_chunks, "pseudorange": _pseudorange_chunks})  # fmt: skip
    try:
        params = RaimParams(mode=settings.raim, p_md=settings.p_md, p_fa=settings.p_fa, fde=settings.fde,
                            p_sat=settings.p_sat, p_const=settings.p_const,
                            sources=LEVELS.get(settings.integrity_sources))  # "auto" (or a bad value, refused below): None
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    tariff_doc = load_tariff(tariff)
    check_settings(settings, tariff_doc)
    with _GeoObjectsAhead(geo, geo_sha256, tariff_doc) as geo_ahead, LogRun(log, settings.input_format) as run:
        # the log opened once, hashed as it is read (io.log_run); the geo-objects loaded meanwhile (_GeoObjectsAhead)
        kind = run.kind
        osnma = osnma_evidence(log, kind, osnma_merkle, osnma_public_keys, auto=osnma_auto, required=settings.require_authenticated,
                               strict=settings.strict, run=run)  # fmt: skip
        auth_counts: dict[str, int] = {}
        failure_fixes: list[pd.DataFrame] = []  # the fixes the OSNMA failures are placed at (a few rows per chunk)
        stats = None
        nominal = NominalModel()
        epoch_raim = replace(params, fde=False)
        finding_settings = FindingSettings.for_class(settings.vehicle_class)
        ignored: dict[str, list[int]] = {}  # receiver outputs that were no evidence: note → [epochs, first line]
        track = TrackExtent()  # where the log was, said when it came near no geo-object
        with run.named_errors():  # one charge for every input kind: its chunks of epochs and measurements, streamed
            stats = ReadStats()  # what the reader passed over (a pseudorange log: its malformed lines)
            placed: dict[str, str] = {}  # how a pseudorange log's epochs were placed: positioning, and a note why not
            charger = None if kind in NAVIGATION_KINDS else TailCharger(geo_ahead.result(), settings, roads, rounds=STREAM_ROUNDS)
            chunks = (_navigation_chunks(run, kind, settings, nominal, stats) if kind in NAVIGATION_KINDS
                      else _pseudorange_chunks(run, kind, nav, settings, nominal, placed, charger, stats))  # fmt: skip
            # a navigation log's next chunk read (and its measurements made) on a second thread while this one is
            # prepared and charged (:func:`_prepared_chunks`: why the preparing is not on that thread)
            with (read_ahead(chunks) if kind in NAVIGATION_KINDS else contextlib.nullcontext(chunks)) as read:
                geo_objects = geo_ahead.result()  # (its first chunks read meanwhile)
                charger = charger or TailCharger(geo_objects, settings, roads, rounds=STREAM_ROUNDS)
                prepared = _prepared_chunks(read, settings, params, model_column=epoch_table is not None)
                params = _charge_chunks(prepared, settings, geo_objects, params, epoch_raim, charger, epoch_table, osnma,
                                        auth_counts, failure_fixes, ignored, track)  # fmt: skip
            if kind in NAVIGATION_KINDS:
                check_usable(stats)
        stats.source, stats.first_problem = run.named(stats.source), run.named(stats.first_problem)  # (not the log's copy)
        policy, table, details, found, period = charger.finish()
        step_s = charger.step_s
        log_sha256 = run.sha256
        decoded_by = run.decoded_by
    inputs = {"log": printable_path(log), "geoobjects": printable_path(geo), "tariff": printable_path(tariff),
              "geoobjects_sha256": geo_objects.source_sha256 or file_sha256(geo), "tariff_sha256": file_sha256(tariff),
              "geoobjects_store_sha256": geo_objects.store_sha256}  # fmt: skip
    if log != "-":  # (a log read from stdin cannot be found again: its invoice records no digest to verify against)
        inputs["log_sha256"] = log_sha256
    if decoded_by:  # a binary protocol read through gpsd's decoder: another version may read other positions
        inputs["log_decoded_by"] = decoded_by
    if isinstance(nav, str):
        inputs.update(nav=printable_path(nav), nav_sha256=file_sha256(nav))
    elif nav is not None:  # several navigation files, read as one
        inputs.update(nav=[printable_path(p) for p in nav], nav_sha256=[file_sha256(p) for p in nav])
    if osnma is not None:
        inputs.update(osnma_inputs(osnma))
    if roads is not None:
        inputs.update(roads=printable_path(roads), roads_sha256=file_sha256(roads))
    inputs.update({k: v for k, v in (as_recorded or {}).items() if k in inputs})
    parameters = {**asdict(settings), "valid_statuses": ["valid", "excluded_valid"], "policy_used": policy,
                  "integrity_sources_used": level_name(params.sources) or "residual"}  # fmt: skip
    if settings.input_format == "auto":
        del parameters["input_format"]  # recorded only when given: invoices of auto-recognised logs stay as they were
    if settings.continued is None:
        del parameters["continued"]  # recorded only by an invoice that continues a passage of the log before
    if settings.vehicle_attrs is None:
        del parameters["vehicle_attrs"]  # recorded only for a tariff of per-km tables
    if not settings.require_authenticated:
        del parameters["require_authenticated"]  # recorded only when required: invoices made before it stay as they were
    positioning_used = placed.get("positioning", "snapshot")
    refused = placed.get("note")  # why no trajectory placed the log's epochs
    if kind in NAVIGATION_KINDS or (positioning_used == "snapshot" and settings.positioning in ("auto", "snapshot") and not refused):
        del parameters["positioning"]  # a receiver's positions, or snapshot ones as before: recorded as they were
    else:
        parameters["positioning_used"] = positioning_used
        if refused:
            parameters["positioning_note"] = refused
        if charger.passages.tc_s != settings.tc_s:  # a trajectory's errors stay correlated longer than --tc
            parameters["tc_used_s"] = charger.passages.tc_s
    invoice = build_invoice(table, None, geo_objects, tariff_doc,
                            vehicle=settings.vehicle or printable_path(os.path.basename(log)), vehicle_class=settings.vehicle_class,
                            inputs=inputs, parameters=parameters, period=period, details=details,
                            continued=settings.continued, vehicle_attrs=settings.vehicle_attrs)  # fmt: skip
    if osnma is not None:
        found = sorted([*found, *failure_findings(osnma, pd.concat(failure_fixes, ignore_index=True))], key=lambda f: (f["start_utc"], f["kind"]))
    if osnma is not None or settings.require_authenticated:
        record_in_invoice(invoice, osnma, auth_counts, settings.require_authenticated)
    invoice["findings"] = {"settings": asdict(finding_settings), "items": found}
    if ignored:
        invoice["receiver_notes"] = receiver_notes(ignored)
    if kind == "gpsd-json" and parameters["integrity_sources_used"] != "residual":
        invoice["receiver_notes"] = {**invoice.get("receiver_notes", {}), "gpsd_json": GPSD_DROPPED}
    if not invoice["lines"] and not invoice["not_charged"]:  # nothing seen: say where the track was
        invoice["nothing_seen"] = track.report(geo_objects)
    _check_notes(invoice, period, step_s)
    explain_not_charged(invoice)
    return seal(invoice), stats


def _check_notes(invoice: dict, period, step_s: float | None) -> None:
    """What the speed and map-matching verdicts an invoice shows mean — the faults that kept positions out and why a
    check did not check — in its ``status_notes`` (a log shorter than the speed window says it is short)."""
    from tollcli.integrity.speed import SpeedParams, speed_status_notes
    from tollcli.integrity.verdict import MM_MEANINGS

    seen = {status for passage in (*invoice["lines"], *invoice["not_charged"]) for status in passage["statuses"]}
    seen |= {why for line in invoice["lines"] for why in (line.get("checks") or {}).get("not_checked", {})}
    duration = (pd.Timestamp(period[1]) - pd.Timestamp(period[0])).total_seconds() if period else None
    notes = speed_status_notes(seen, duration, step_s, SpeedParams())
    notes.update({k: v for k, v in MM_MEANINGS.items() if k in seen})
    if notes:
        invoice["status_notes"] = {**(invoice.get("status_notes") or {}), **notes}


#: epoch columns kept for the whole log after its chunks are read (policy checks, findings, the invoice's period)
KEPT_EPOCH_COLUMNS = ("epoch", "time_utc", "tod_s", "line", "lat_deg", "lon_deg", "fix_valid", "n_used", "hdop", "speed_mps",
                      "course_deg", "sigma_major_m", "pos_disagreement_m", "date_disagreement_days", "date_jump_days",
                      "snapshot_lat_deg", "snapshot_lon_deg")  # fmt: skip
#: per-epoch RAIM columns kept (the policy checks and the findings use them)
KEPT_RAIM_COLUMNS = ("raim_status", "n_used", "test_stat", "threshold", "p_fa", "test_stat_source", "separation_ratio")
#: epochs per chunk: the working set of the satellite-level steps (an hour at 1 Hz)
CHUNK_EPOCHS = 3_600
#: bytes read at a time (a chunk ends at a block's end: tests make both small to cut logs often)
BLOCK_BYTES = SOURCE_BLOCK_BYTES
#: False: the charger keeps every chunk and charges the whole log at once (the reference the tests compare with)
STREAM_ROUNDS = True


def _navigation_chunks(run: LogRun, kind: str, settings: ChargeSettings, nominal: NominalModel,
                       stats: ReadStats) -> Iterator[tuple[pd.DataFrame, Measurements, pd.DataFrame | Columns | None]]:  # fmt: skip
    """A navigation log's (NMEA, u-blox NAV, gpsd JSON, RTKLIB: ``kind``) chunks as they are read: each chunk's epochs,
    its RAIM measurements and its satellite table as the reader made it (a DataFrame, or the NMEA reader's
    :class:`~tollcli.io.columns.Columns`: building a frame of 1.5 million rows for the 10 h drive of
    ``benchmarks/process_throughput.py`` took 0.25–0.3 s of the reading thread), ``stats`` counting what the reader saw."""
    date = dt.date.fromisoformat(settings.date) if settings.date else None
    model = settings.sigma_model if settings.sigma_model != "input" else "nominal"
    carry = AngleCarry()
    epochs_seen = 0
    for chunk in iter_navigation_tables(run.source(), kind, strict=settings.strict, date=date, stats=stats, chunk_epochs=CHUNK_EPOCHS,
                                        block_bytes=BLOCK_BYTES):  # fmt: skip
        if chunk.epochs.empty:
            continue
        if epochs_seen == 0 and date is not None and kind != "nmea":
            check_given_date(chunk.epochs, run.name, settings.date)
        check_not_future(chunk.epochs, run.name)
        epochs_seen += len(chunk.epochs)
        satellites = chunk.satellites_read  # the reader's columns: no frame is built for numbers only read
        yield chunk.epochs, nmea_measurements(chunk.epochs, satellites, model, settings.sigma_m, nominal, carry=carry), satellites
    if epochs_seen == 0:
        check_usable(stats)
        raise DataError(f"{run.name}: no epoch with a time of day")


def _pseudorange_chunks(run: LogRun, kind: str, nav: str | tuple[str, ...] | None, settings: ChargeSettings,
                        nominal: NominalModel, placed: dict[str, str], charger: TailCharger,
                        stats: ReadStats) -> Iterator[tuple[pd.DataFrame, Measurements, None]]:  # fmt: skip
    """A pseudorange log's (RINEX, GnssLogger, GSDC, u-blox RAWX, libRSF) epochs and measurements, in chunks of
    :data:`CHUNK_EPOCHS` epochs. The positions are solved from the run's replay, a long log segment by segment
    (:mod:`tollcli.job.pseudorange_segments`) — each epoch alone (snapshot WLS), then placed by the
    trajectory estimator (``settings.positioning``, :func:`~tollcli.integrity.trajectory.with_trajectory`; ``placed`` receives the positioning
    it used and the note why a trajectory was refused, and ``charger`` counts positions as independent evidence only the trajectory's correlation time apart);
    from there on the chunks take the same path as a navigation log's. ``stats`` counts the lines (records, frames) the
    reader passed over as malformed."""
    try:
        placed_log = placed_pseudorange_log(run.replay_path(), kind, nav, settings.sigma_model, settings.sigma_m, nominal, settings.strict,
                                            settings.positioning)  # fmt: skip
    except NoOrbitsError as exc:
        solutions = solutions_instead(run.replay_path(), kind, nav)
        if not solutions:
            raise
        # the pseudoranges cannot be solved without orbits, but the receiver solved them: its own fixes are charged
        placed["positioning"] = "receiver"
        placed["note"] = (f"{str(exc).replace(run.replay_path(), run.name)}: the receiver's own solutions ({', '.join(solutions)}, "
                          f"with its NAV-SAT residuals where it wrote them) were charged instead; --nav gives the orbits")  # fmt: skip
        yield from _navigation_chunks(run, "ubx-nav", settings, nominal, stats)
        return
    stats.source, stats.malformed = run.name, stats.malformed + placed_log.skipped_lines
    with placed_log:
        placed["positioning"] = placed_log.positioning
        if placed_log.note:
            placed["note"] = placed_log.note
        if placed_log.correlation_s is not None:
            charger.independent_after(placed_log.correlation_s)
        first = True
        for part, part_meas in placed_log.chunks(CHUNK_EPOCHS):
            if kind in RELATIVE_CLOCK_KINDS:
                part = on_the_clock(part, run.name, settings)
            elif settings.date is not None and first:
                check_given_date(part, run.name, settings.date)
            check_not_future(part, run.name)
            first = False
            yield part, part_meas, None


class _GeoObjectsAhead:
    """The geo-object file ``geo`` hashed on a thread of its own while the log is opened and its first chunks read;
    :meth:`result` then loads its geo-objects (:func:`load_geoobjects`: the store the digest names, mapped, or compiled
    here) and checks them against the tariff.

    Hashing a national network's GeoJSON (437 MB at 150 000 sections) takes ~0.4 s, which the hash's C code spends
    without the interpreter lock, beside the reading. Only the hash runs there: a first run's compiling stays on the
    calling thread, where Ctrl-C stops it. What is said stays as before: leaving the block by an error (the log's,
    say) raises the geo-objects' or the tariff's own error first, as when they were loaded before the log was opened."""

    def __init__(self, geo: str, sha256: str | None, tariff_doc):
        from concurrent.futures import ThreadPoolExecutor

        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="tollcli-geo-digest")
        self._digest = self._pool.submit(_digest_or_none, geo) if sha256 is None else None
        self._geo, self._sha256, self._tariff, self._loaded = geo, sha256, tariff_doc, None

    def result(self):
        """The geo-objects, checked against the tariff (raising either's error)."""
        if self._loaded is None:
            digest = self._sha256 if self._digest is None else self._digest.result()
            geo_objects = load_geoobjects(self._geo, sha256=digest)
            self._tariff.check_against(geo_objects.ids, geo_objects.road_class, self._geo)
            self._loaded = geo_objects
        return self._loaded

    def __enter__(self) -> _GeoObjectsAhead:
        return self

    def __exit__(self, kind, error, trace) -> None:
        try:
            if kind is not None and issubclass(kind, Exception) and self._loaded is None:
                self.result()  # the geo-objects' or the tariff's error first, as before; else the block's own
        finally:
            self._pool.shutdown(wait=True)


def _digest_or_none(path: str) -> str | None:
    """The file's SHA-256, or None where it cannot be read (:func:`load_geoobjects` then says why)."""
    try:
        return file_sha256(path)
    except OSError:
        return None


@dataclass
class PreparedChunk:
    """A chunk of a log with what needs no geo-object (:func:`_prepared_chunks`)."""

    epochs: pd.DataFrame
    meas: Measurements
    satellites: pd.DataFrame | Columns | None
    params: RaimParams  # the integrity sources the log settled on so far
    env_columns: pd.DataFrame  # the measured environment's column
    geometry: Geometry  # the WLS geometry, once for the epoch RAIM and every HAL
    cn0: pd.DataFrame  # the per-epoch C/N0 summary (:func:`~tollcli.enforcement.trip.cn0_summary`)
    model_hpl_m: np.ndarray | None  # the model level's HPL (:func:`~tollcli.integrity.run.model_hpl`; None: a trajectory's positions)


def _prepared_chunks(chunks, settings: ChargeSettings, params: RaimParams, model_column: bool = True) -> Iterator[PreparedChunk]:
    """Each chunk (epochs, RAIM measurements, satellite table or None) with what needs no geo-object: the integrity
    sources the log settled on so far (``params``), its measured environment (the σ of the epochs the residuals say
    urban, and that column), its WLS geometry, its C/N0 summary and its model level's HPL. Chunks in order: the
    environment carries from one to the next. ``model_column`` False: the caller keeps no ``hpl_model_m`` column (no
    epoch table), so the model level's HPL is solved only where a verdict can read it (:func:`model_level_read`), NaN
    elsewhere: a log the receiver's RAIM (GBS) or a residual test vouches for has none to solve.

    Made on the thread that charges, not on the reading thread: the reading (the NMEA reader and the measurements) is
    the longer half, and with this on its side the charging thread waited for chunks. ``process`` of the 10 h NEO-M9N
    drive of ``benchmarks/process_throughput.py`` (828 000 lines, 10 000 geo-objects, warm), pairs run in turn: wall
    time 0.89 of the layout before (8 pairs, median of the pairs' ratios; 3.69 s against 4.36 s) and 0.92 (10 pairs
    against the code before in a worktree; 3.76 against 4.18 s), the same invoice bytes; with the measurements also made
    on the charging thread 1.09 of this, with the environment and the WLS geometry on the reading thread 1.05. (The
    reading thread held all of it once, when the RAIM took longer: the balance moves as either side gets faster.)"""
    env_carry = EnvironmentCarry()
    for epochs, meas, satellites in chunks:
        params = settle_sources(params, meas)  # the log's level, from its first epoch with a source
        meas, env_columns = measured_environment(epochs, meas, settings.environment, env_carry)
        geometry = wls_geometry(meas.H, meas.sigma_m, meas.mask)
        model = None  # a trajectory's positions: its own bound
        if meas.trajectory_hpl_m is None:
            read = model_column or model_level_read(params)
            model = model_hpl(meas, geometry, params.p_md) if read else np.full(meas.mask.shape[0], np.nan)
        yield PreparedChunk(epochs, meas, satellites, params, env_columns, geometry,
                            cn0_summary(satellites, len(epochs), int(epochs["epoch"].iat[0])), model)  # fmt: skip


def _charge_chunks(chunks, settings: ChargeSettings, geo, params: RaimParams, epoch_raim: RaimParams, charger: TailCharger,
                   epoch_table: list | None = None, osnma: OsnmaEvidence | None = None, auth_counts: dict | None = None,
                   failure_fixes: list | None = None, ignored: dict | None = None,
                   track: TrackExtent | None = None) -> RaimParams:  # fmt: skip
    """Charge a log chunk by chunk (``chunks``: :func:`_prepared_chunks`): each chunk's RAIM, geo-object pairs and
    OSNMA authentication are done before the next, and handed to ``charger`` with the few per-epoch columns it needs.

    Memory is the chunk's and the charger's tail, not the log's (``epoch_table``, a list for batch
    outputs, receives the whole per-epoch table and so grows with the log). Returns ``params`` with the integrity
    sources the log settled on.
    """
    table_parts = []
    offset = 0
    warm_up(geo)  # while the first chunk is read
    for chunk in chunks:
        epochs, meas, satellites, params, env_columns, geometry = (chunk.epochs, chunk.meas, chunk.satellites, chunk.params,
                                                                   chunk.env_columns, chunk.geometry)  # fmt: skip
        epoch_raim = replace(epoch_raim, sources=params.sources)
        # once for the epoch RAIM and every HAL; an epoch's HPL where no residual test decides is read only by map
        # matching's bound and an epoch table: without them it is not solved
        hal_free = hal_free_terms(meas, epoch_raim, geometry, chunk.model_hpl_m, untested=epoch_table is not None or charger.roads_path is not None)
        raim = run_raim(meas, epoch_raim, geometry=geometry, hal_free=hal_free)
        pairs = inside_pairs(epochs, meas, geo, params, row_offset=offset, geometry=geometry, environment=settings.environment,
                             hal_free=hal_free)  # fmt: skip
        cn0 = chunk.cn0
        kept = epochs[[c for c in KEPT_EPOCH_COLUMNS if c in epochs]]
        auth = None
        if osnma is not None or settings.require_authenticated:
            auth = not_checked(len(epochs)) if osnma is None else epoch_authentication(meas, epochs, osnma.authenticated_for(satellites),
                                                                                                        settings.p_fa, geometry)
            kept = kept.assign(nav_auth=auth["nav_auth"].to_numpy())
            if osnma is not None and failure_fixes is not None:
                failure_fixes.append(fixes_before(epochs, osnma.failure_times))
            for status, n in auth["nav_auth"].value_counts().items():
                auth_counts[status] = auth_counts.get(status, 0) + int(n)
        charger.add(kept, raim[list(KEPT_RAIM_COLUMNS)], cn0, pairs)
        if ignored is not None:
            count_ignored(raim, epochs, ignored)
        if track is not None and "lon_deg" in epochs:
            track.add(epochs["lon_deg"].to_numpy(float), epochs["lat_deg"].to_numpy(float))
        if epoch_table is not None:
            table_parts.append(pd.concat([epochs.reset_index(drop=True).rename(columns={"n_used": "n_used_receiver"}),
                                          env_columns, raim.reset_index(drop=True), *([auth] if auth is not None else [])],
                                         axis=1))  # fmt: skip
        offset += len(epochs)
        del chunk, epochs, meas, geometry, hal_free, raim, pairs, cn0  # freed before the next chunk is read, not after
    if epoch_table is not None and table_parts:
        epoch_table.append(pd.concat(table_parts, ignore_index=True))
    return params


def settings_from_invoice(invoice: dict) -> ChargeSettings:
    """The settings an invoice was made with."""
    recorded = invoice.get("parameters") or {}
    if not isinstance(recorded, dict):
        raise DataError("the invoice's parameters are not a table of settings")
    fields = ChargeSettings.__dataclass_fields__
    settings = ChargeSettings(**{k: recorded[k] for k in fields if k in recorded})
    if "environment" not in recorded:  # an invoice from before the environment was measured: the nominal model throughout
        settings.environment = "open"
    if "positioning" not in recorded:  # a navigation log's, or from before the trajectory estimator: snapshot positions
        settings.positioning = "snapshot"
    return settings


