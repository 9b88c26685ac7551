"""The whole charging job as one function: log + geo-objects + tariff → invoice (used by process and verify)."""

from __future__ import annotations

import datetime as dt
import hashlib
import os
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from tollcli.charging.invoice import build_invoice, file_sha256, invoice_json, seal
from tollcli.charging.recognition import charges, load_geoobjects, recognise
from tollcli.charging.tariffs import load_tariff
from tollcli.errors import UsageError
from tollcli.integrity.pseudorange_inputs import pseudorange_epochs
from tollcli.io.sources import sniff_format
from tollcli.integrity.from_nmea import nmea_measurements
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim
from tollcli.enforcement.findings import FindingSettings, trip_findings
from tollcli.integrity.sigma_models import NominalModel
from tollcli.nmea import ReadStats, read_nmea
from tollcli.nmea.reader import check_usable


@dataclass
class ChargeSettings:
    """Everything besides the input files that decides an invoice (recorded in it, for ``verify``)."""

    vehicle_class: str = "car"
    vehicle: str | None = None
    raim: str = "etc"
    p_md: float = 5e-5
    p_fa: float = 5e-3
    fde: bool = False
    sigma_model: str = "nominal"
    sigma_m: float = 5.0
    tc_s: float = 5.0
    n_th: int = 1
    strict: bool = False
    date: str | None = None  # YYYY-MM-DD for logs without dates
    policy: str | None = None  # which checks a position must pass (None: the strictest the inputs support)


def content_sha256(invoice: dict) -> str:
    """SHA-256 of the invoice's canonical JSON without its own ``content_sha256``."""
    body = {k: v for k, v in invoice.items() if k != "content_sha256"}
    return hashlib.sha256(invoice_json(body).encode("utf-8")).hexdigest()


def charge_log(log: str, geo: str, tariff: str, settings: ChargeSettings, nav: str | None = None,
               roads: str | None = None, epoch_table: list | None = None) -> tuple[dict, ReadStats | None]:  # fmt: skip
    """The invoice for one log (with its content hash) and the reader's statistics (NMEA).

    ``epoch_table``: a list that receives the per-epoch table (epochs + RAIM columns) for batch outputs.
    """
    try:
        params = RaimParams(mode=settings.raim, p_md=settings.p_md, p_fa=settings.p_fa, fde=settings.fde)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    geo_objects = load_geoobjects(geo)
    tariff_doc = load_tariff(tariff)
    kind = sniff_format(log)
    stats = None
    nominal = NominalModel()
    if kind == "nmea":
        date = dt.date.fromisoformat(settings.date) if settings.date else None
        tables = read_nmea(log, strict=settings.strict, date=date)
        check_usable(tables.stats)
        stats = tables.stats
        epochs = tables.epochs
        model = settings.sigma_model if settings.sigma_model != "input" else "nominal"
        meas = nmea_measurements(epochs, tables.satellites, model, settings.sigma_m, nominal)
    else:
        epochs, meas = pseudorange_epochs(log, kind, nav, settings.sigma_model, settings.sigma_m, nominal)
    per_epoch = run_raim(meas, RaimParams(mode=settings.raim, p_md=settings.p_md, p_fa=settings.p_fa))
    policy, why, matched = _policy_checks(epochs.assign(raim_status=per_epoch["raim_status"].to_numpy()), settings, roads)
    positions = recognise(epochs, meas, geo_objects, params, tc_s=settings.tc_s, n_th=settings.n_th,
                          epoch_why=why, matched_road=matched)  # fmt: skip
    finding_settings = FindingSettings.for_class(settings.vehicle_class)
    found = trip_findings(epochs, tables.satellites if kind == "nmea" else None, per_epoch, geo_objects, finding_settings)
    table = charges(positions, settings.n_th)
    dated = epochs["time_utc"].dropna()
    inputs = {"log": log, "geoobjects": geo, "tariff": tariff,
              "geoobjects_sha256": file_sha256(geo), "tariff_sha256": file_sha256(tariff)}  # fmt: skip
    if log != "-":
        inputs["log_sha256"] = file_sha256(log)
    if nav is not None:
        inputs.update(nav=nav, nav_sha256=file_sha256(nav))
    if roads is not None:
        inputs.update(roads=roads, roads_sha256=file_sha256(roads))
    parameters = {**asdict(settings), "valid_statuses": ["valid", "excluded_valid"], "policy_used": policy}
    invoice = build_invoice(table, positions, geo_objects, tariff_doc,
                            vehicle=settings.vehicle or os.path.basename(log), vehicle_class=settings.vehicle_class,
                            inputs=inputs, parameters=parameters,
                            period=(dated.min(), dated.max()) if len(dated) else None)  # fmt: skip
    invoice["findings"] = {"settings": asdict(finding_settings), "items": found}
    invoice = seal(invoice)
    if epoch_table is not None:
        epoch_table.append(pd.concat([epochs.reset_index(drop=True).rename(columns={"n_used": "n_used_receiver"}), per_epoch], axis=1))
    return invoice, stats


def _policy_checks(epochs, settings: ChargeSettings, roads: str | None):
    """The policy in force, each epoch's failed check ('' when none) and matched road (None without roads)."""
    from tollcli.integrity.map_matching import load_roads
    from tollcli.integrity.verdict import POLICIES, default_policy, epoch_checks, failed_check

    has_speed = "speed_mps" in epochs and bool(np.isfinite(epochs["speed_mps"].to_numpy(float)).mean() > 0.5)
    policy = settings.policy or default_policy(has_speed, roads is not None)
    if policy not in POLICIES:
        raise UsageError(f"--policy {policy}: one of {', '.join(POLICIES)}")
    needs = POLICIES[policy]
    if "mm" in needs and roads is None:
        raise UsageError(f"--policy {policy} needs the road network (--roads)")
    if "speed" in needs and not has_speed:
        raise UsageError(f"--policy {policy}: the log has no speed over ground (RMC/VTG) to check")
    if not needs:
        return policy, None, None
    checks = epoch_checks(epochs, load_roads(roads) if "mm" in needs else None)
    matched = checks["matched_road"].astype(str).to_numpy(dtype=object) if "mm" in needs else None
    return policy, failed_check(checks, policy), matched


def settings_from_invoice(invoice: dict) -> ChargeSettings:
    """The settings an invoice was made with."""
    recorded = invoice.get("parameters") or {}
    fields = ChargeSettings.__dataclass_fields__
    return ChargeSettings(**{k: recorded[k] for k in fields if k in recorded})


