"""The enforcement commands' jobs on one log, each read once through its :class:`~tollcli.io.log_run.LogRun`:
where a vehicle was (``locate``), the trip's tamper and evasion findings with its OSNMA failures (``findings``),
and the cross-check of roadside tag reads against the trip (``enforce``)."""

from __future__ import annotations

import pandas as pd

from tollcli.enforcement.findings import FindingSettings, trip_findings
from tollcli.enforcement.locate import vehicle_in_head
from tollcli.enforcement.roadside import RoadsideSettings, cross_check, read_gantries, read_reads
from tollcli.io.log_run import LogRun
from tollcli.job.log_integrity import trip_tables


def locate_log(log: str, hal_m: float, strict: bool = False, date=None) -> tuple[pd.DataFrame, str | None]:
    """The trip's integrity table (RAIM at ``hal_m``) and the vehicle id its header names (``# vehicle: ID``), or None."""
    with LogRun(log) as run:
        header = vehicle_in_head(run.head()) if log != "-" else None
        table, _ = trip_tables(run, hal_m, strict, date)
    return table, header


def log_findings(log: str, settings: FindingSettings, hal_m: float = 50.0, strict: bool = False, date=None,
                 geo: str | None = None, osnma_merkle: str | None = None,
                 osnma_public_keys: list[str] | None = None) -> list[dict]:  # fmt: skip
    """The trip's findings (:func:`~tollcli.enforcement.findings.trip_findings`: gaps, jamming and spoofing signs; the
    geo-objects of ``geo`` a gap could have crossed) and, for a u-blox log with the OSNMA keys, its OSNMA failures;
    in time order."""
    from tollcli.charging.recognition import load_geoobjects
    from tollcli.job.osnma_evidence import failure_findings, osnma_evidence

    with LogRun(log) as run:  # the OSNMA pages and the trip read the same bytes
        evidence = osnma_evidence(log, run.kind, osnma_merkle, osnma_public_keys, strict=strict, run=run)
        epochs, satellites = trip_tables(run, hal_m, strict, date)
    if epochs.empty:
        return []
    items = trip_findings(epochs, satellites, raim=epochs, geo=load_geoobjects(geo) if geo else None, settings=settings)  # RAIM columns in the table
    if evidence is not None:
        items = sorted([*items, *failure_findings(evidence, epochs)], key=lambda f: (f["start_utc"], f["kind"]))
    return items


def roadside_findings(log: str, reads: str, gantries: str, tag: str | None, settings: RoadsideSettings, hal_m: float = 50.0,
                      strict: bool = False, date=None) -> list[dict]:  # fmt: skip
    """Tag reads (CSV) against the trip: reads where the trip was elsewhere or silent, gantries passed without a read."""
    epochs, _ = trip_tables(log, hal_m, strict, date)
    ids, geoms, crs = read_gantries(gantries)
    return cross_check(epochs, read_reads(reads), ids, geoms, crs, tag, settings)
