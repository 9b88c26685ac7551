"""Everything a figure or report of a run needs, recomputed from the invoice's own inputs and settings.

A run is an invoice written by ``tollcli process``: it names its log and geo-objects
and records every setting, so the per-epoch integrity table is rebuilt exactly as the
charging saw it (with the HAL of the most demanding geo-object for positions outside
any). The truth trajectory is optional.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.charging.audit import load_invoice
from tollcli.charging.recognition import GeoObjects, load_geoobjects
from tollcli.errors import DataError
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.truth_check import check_against_truth, errors_against_truth
from tollcli.io.sources import sniff_format
from tollcli.job.log_integrity import iter_integrity
from tollcli.job.pipeline import settings_from_invoice
from tollcli.job.verify import locate_input
from tollcli.readers.nmea import ReadStats
from tollcli.spatial import read_features


@dataclass
class RunData:
    invoice: dict
    epochs: pd.DataFrame  # integrity table (+ ``t_s`` seconds from the first epoch, ``geoobject`` it lies in or "")
    geo: GeoObjects
    geo_features: list[dict]  # WGS-84 GeoJSON features of the geo-objects
    hal_m: float
    truth: pd.DataFrame | None = None
    truth_check: dict | None = None


def load_run(invoice_path: str, truth_path: str | None = None) -> RunData:
    invoice = load_invoice(invoice_path)
    inputs = invoice.get("inputs") or {}
    log, geo_path = inputs.get("log"), inputs.get("geoobjects")
    if not isinstance(log, str) or not isinstance(geo_path, str) or log == "-":
        raise DataError(f"{invoice_path}: the invoice does not name a log file and geo-objects to rebuild the run from")
    # where the invoice names them, or beside it (an auditor's folder), checked by their recorded SHA-256
    log = locate_input(invoice_path, log, inputs.get("log_sha256"), "log")
    geo_path = locate_input(invoice_path, geo_path, inputs.get("geoobjects_sha256"), "geo-objects")
    settings = settings_from_invoice(invoice)
    geo = load_geoobjects(geo_path)
    hal = float(np.min(geo.hal_m))
    params = RaimParams(mode=settings.raim, hal_m=hal, p_md=settings.p_md, p_fa=settings.p_fa, fde=settings.fde,
                        p_sat=settings.p_sat, p_const=settings.p_const)
    chunks = list(iter_integrity(log, sniff_format(log), params, settings.sigma_model, settings.sigma_m, stats=ReadStats(),
                                 environment=settings.environment))
    epochs = pd.concat([c.table for c in chunks], ignore_index=True) if chunks else pd.DataFrame()
    if epochs.empty:
        raise DataError(f"{log}: no epochs")
    from tollcli.charging.recognition import candidate_pairs
    from tollcli.times import epoch_seconds

    t = epoch_seconds(epochs)
    epochs["t_s"] = t - np.nanmin(t)
    rows, obj, _, _ = candidate_pairs(epochs, geo)
    inside = np.full(len(epochs), "", dtype=object)
    inside[rows[::-1]] = geo.ids[obj[::-1]]  # the first geo-object of each epoch
    epochs["geoobject"] = inside
    truth = check = None
    if truth_path:
        from tollcli.charging.truth_passages import truth_trajectory

        truth = truth_trajectory(truth_path)
        check = check_against_truth(epochs, truth)
        epochs["horiz_error_m"] = errors_against_truth(epochs, truth)[0]
    return RunData(invoice, epochs, geo, read_features(geo_path), hal, truth, check)
