"""Audit invoices: undercharges and overcharges against the truth, or the risk without it.

With truth (the geo-objects really driven: a list of ids, or a truth trajectory
whose positions inside a geo-object mark it driven):

* per geo-object and run: undercharge = driven but not charged (missed
  recognition, MGoR); overcharge = charged but not driven (false recognition, FGoR);
* rates across runs with Wilson 95 % intervals, money per run, and the share of
  invoices whose total is within ``invoice_error_pct`` of the true total
  (ISO/TS 17444-1 style), with its interval.

Without truth, a risk report from the invoices alone:

* revenue at risk: passages where fixes fell inside a geo-object but too few
  valid independent positions remained, with the statuses that explain why;
* per charge, an upper bound on the chance it is false: at least N_Th of its n
  independent valid positions must be misleading, each with probability ≤ P_MD
  even when a fault is present, so P(false) ≤ P(Bin(n, P_MD) ≥ N_Th). That holds for
  positions a fault-detecting source vouched for (a residual test, the receiver's own
  RAIM: the invoice line's ``vouched_by``); a covariance-only bound (GST) detects no
  fault, so its n_cov positions are counted as possibly misleading:
  P(false) ≤ P(Bin(n − n_cov, P_MD) ≥ N_Th − n_cov) (1 when n_cov ≥ N_Th).
"""

from __future__ import annotations

import json
import math
from decimal import Decimal

import numpy as np
import pandas as pd
from scipy import stats

from tollcli.errors import DataError, UsageError
from tollcli.integrity.sources import FAULT_DETECTING
from tollcli.io.sources import read_json
from tollcli.stats import wilson


def load_invoice(path: str) -> dict:
    doc = read_json(path, "an invoice")
    if not isinstance(doc, dict) or "lines" not in doc or "total" not in doc:
        raise DataError(f"{path}: not a tollcli invoice (no lines/total)")
    return doc


def driven_from_truth(path: str, geo) -> set[str]:
    """Truly driven geo-object ids: from a list (JSON array, or one id per line) or a trajectory (CSV/GeoJSON)."""
    from tollcli.charging.recognition import candidate_pairs

    try:
        text = open(path, encoding="utf-8").read()
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: unreadable ({exc})") from None
    stripped = text.strip()
    if stripped.startswith("["):
        ids = json.loads(stripped)
        return {str(i) for i in ids}
    if stripped.startswith("{"):
        doc = json.loads(stripped)
        coords = []
        for feature in doc.get("features", []):
            geom = feature.get("geometry") or {}
            if geom.get("type") == "Point":
                coords.append(geom["coordinates"][:2])
            elif geom.get("type") == "LineString":
                coords.extend(c[:2] for c in geom["coordinates"])
        points = pd.DataFrame(coords, columns=["lon_deg", "lat_deg"]) if coords else pd.DataFrame(columns=["lon_deg", "lat_deg"])
    else:
        first = stripped.splitlines()[0] if stripped else ""
        if "lat" not in first.lower():
            return {line.strip() for line in stripped.splitlines() if line.strip() and not line.startswith("#")}
        table = pd.read_csv(path)
        lat = next((c for c in table.columns if c.lower() in ("lat_deg", "latdeg", "lat", "latitude")), None)
        lon = next((c for c in table.columns if c.lower() in ("lon_deg", "lngdeg", "lon", "lng", "longitude")), None)
        if lat is None or lon is None:
            raise DataError(f"{path}: a truth trajectory needs latitude and longitude columns")
        heading = next((c for c in table.columns if c.lower() in ("heading_deg", "course_deg")), None)
        points = table.rename(columns={lat: "lat_deg", lon: "lon_deg"})[["lat_deg", "lon_deg"]]
        if heading is not None:
            points = points.assign(course_deg=table[heading].to_numpy(float))
    if points.empty:
        return set()
    points = points.astype(float)
    rows, obj, px, py = candidate_pairs(points, geo)
    directed = geo.directed()[obj]
    if directed.any():  # a carriageway is driven only in its direction of travel (carriageways.py)
        from tollcli.charging.carriageways import direction_check

        course = points["course_deg"].to_numpy() if "course_deg" in points else track_deg(points)
        ok = direction_check(geo.axes[obj[directed]], px[directed], py[directed], course[rows[directed]],
                             np.full(int(directed.sum()), 1e9)) == ""  # a trajectory: its course is the truth  # fmt: skip
        keep = ~directed
        keep[directed] = ok
        obj = obj[keep]
    return {str(geo.ids[i]) for i in np.unique(obj)}


def track_deg(points: pd.DataFrame) -> np.ndarray:
    """The direction of travel at each point of a trajectory (towards the next point; the last repeats), degrees
    from north; NaN where the vehicle does not move."""
    lat, lon = np.radians(points["lat_deg"].to_numpy(float)), np.radians(points["lon_deg"].to_numpy(float))
    if lat.size < 2:
        return np.full(lat.size, np.nan)
    dn, de = np.diff(lat), np.diff(lon) * np.cos((lat[1:] + lat[:-1]) / 2)
    track = np.where(np.hypot(dn, de) > 0, np.degrees(np.arctan2(de, dn)) % 360.0, np.nan)
    return np.append(track, track[-1])


def truth_span(path: str) -> tuple[pd.Timestamp, pd.Timestamp, set[str]] | None:
    """First and last time of a truth trajectory CSV (``time_utc``, ``time`` or ``timestamp``) and its vehicle ids
    (a ``vehicle`` column; empty when none); None for an id list or a trajectory without times."""
    try:
        with open(path, encoding="utf-8") as fh:
            first = fh.readline()
    except (OSError, UnicodeDecodeError):
        return None
    if first.lstrip().startswith(("[", "{")) or "lat" not in first.lower():
        return None
    table = pd.read_csv(path)
    column = next((c for c in table.columns if c.lower() in ("time_utc", "time", "timestamp")), None)
    if column is None:
        return None
    times = pd.to_datetime(table[column], utc=True, errors="coerce").dropna()
    if times.empty:
        return None
    vehicles = {str(v) for v in table["vehicle"].dropna()} if "vehicle" in table else set()
    return times.min(), times.max(), vehicles


def check_same_trip(invoices: list[dict], names: list[str], truth: str) -> None:
    """DataError unless every invoice's period overlaps the truth's times (and its vehicle is the truth's, when
    the truth names one): comparing a 2024 invoice with a 2026 drive says nothing."""
    span = truth_span(truth)
    if span is None:
        return
    start, end, vehicles = span
    for invoice, name in zip(invoices, names):
        period = invoice.get("period") or {}
        try:
            a, b = pd.Timestamp(period["start_utc"]), pd.Timestamp(period["end_utc"])
        except (KeyError, TypeError, ValueError):
            raise DataError(f"{name}: the invoice has no period to compare with the truth {truth}") from None
        if b < start or a > end:
            raise DataError(f"{name}: the invoice covers {period['start_utc']} – {period['end_utc']}, the truth {truth} "
                            f"{start:%Y-%m-%dT%H:%M:%SZ} – {end:%Y-%m-%dT%H:%M:%SZ}: not the same trip")  # fmt: skip
        if vehicles and str(invoice.get("vehicle")) not in vehicles:
            raise DataError(f"{name}: vehicle {invoice.get('vehicle')!r} is not the truth's ({', '.join(sorted(vehicles))})")


def audit_with_truth(invoices: list[dict], driven: set[str], fees: dict[str, Decimal], invoice_error_pct: float = 1.0) -> dict:
    """Under/overcharges per geo-object and per run against the truly driven set."""
    charged_sets = [{line["geoobject"] for line in inv["lines"]} for inv in invoices]
    every = sorted(driven.union(*charged_sets)) if charged_sets else sorted(driven)
    n = len(invoices)
    per_object = []
    for gid in every:
        was_driven = gid in driven
        n_charged = sum(gid in s for s in charged_sets)
        n_under = (n - n_charged) if was_driven else 0
        n_over = 0 if was_driven else n_charged
        misses = n_under if was_driven else n_over
        low, high = wilson(misses, n)
        per_object.append({
            "geoobject": gid, "driven": was_driven, "runs": n, "charged": n_charged,
            "undercharges": n_under, "overcharges": n_over,
            "rate": misses / n if n else 0.0, "rate_ci95": [low, high],
            "error_kind": "missed recognition" if was_driven else "false recognition",
        })  # fmt: skip
    true_total = sum((fees.get(g, Decimal(0)) for g in driven), Decimal(0))
    per_run, within = [], 0
    for inv, charged in zip(invoices, charged_sets):
        under = sorted(driven - charged)
        over = sorted(charged - driven)
        causes = [{"geoobject": g, **undercharge_cause(inv, g)} for g in under]
        money_under = sum((fees.get(g, Decimal(0)) for g in under), Decimal(0))
        money_over = sum((Decimal(line["fee"]) for line in inv["lines"] if line["geoobject"] in over), Decimal(0))
        total = Decimal(inv["total"])
        error_pct = float(abs(total - true_total) / true_total * 100) if true_total else (0.0 if total == 0 else math.inf)
        within += error_pct <= invoice_error_pct
        per_run.append({"vehicle": inv.get("vehicle", ""), "total": str(total), "true_total": str(true_total),
                        "undercharged": under, "undercharge_causes": causes, "overcharged": over, "money_under": str(money_under),
                        "money_over": str(money_over), "error_pct": error_pct})  # fmt: skip
    low, high = wilson(within, n)
    return {
        "runs": n, "driven": sorted(driven), "geoobjects": per_object, "invoices": per_run,
        "invoice_error_pct": invoice_error_pct, "share_within": within / n if n else 0.0, "share_within_ci95": [low, high],
        "missed_recognitions": sum(o["undercharges"] for o in per_object),
        "false_recognitions": sum(o["overcharges"] for o in per_object),
    }  # fmt: skip


def undercharge_cause(invoice: dict, gid: str) -> dict:
    """Why a driven geo-object is not on the invoice, from the invoice's own ``not_charged`` evidence."""
    n_th = int((invoice.get("parameters") or {}).get("n_th", 1))
    seen = [item for item in invoice.get("not_charged", []) if item["geoobject"] == gid]
    if not seen:
        return {"cause": "no position inside the geo-object (no fix there, or every fix fell outside it)",
                "n_inside": 0, "n_valid": 0, "statuses": {}}  # fmt: skip
    n_inside = sum(int(i["n_inside"]) for i in seen)
    n_valid = sum(int(i["n_valid"]) for i in seen)
    statuses: dict[str, int] = {}
    for item in seen:
        for k, v in item.get("statuses", {}).items():
            statuses[k] = statuses.get(k, 0) + int(v)
    if n_valid == 0:
        listed = ", ".join(f"{k} {v}" for k, v in sorted(statuses.items()))
        cause = f"{n_inside} positions inside, none valid ({listed})"
    else:
        best = max(int(i["n_valid_independent"]) for i in seen)
        cause = f"{n_valid} valid positions inside but only {best} independent in a passage (N_Th = {n_th})"
    return {"cause": cause, "n_inside": n_inside, "n_valid": n_valid, "statuses": statuses}


def findings_of(invoices: list[dict]) -> list[dict]:
    """The tamper/evasion findings the invoices carry, with their vehicle."""
    return [{"vehicle": inv.get("vehicle", ""), **item} for inv in invoices for item in (inv.get("findings") or {}).get("items", [])]


def risk_report(invoices: list[dict], fees: dict[str, Decimal]) -> dict:
    """Revenue at risk and per-charge bounds on a false charge, from invoices alone."""
    at_risk, charges = [], []
    money = Decimal(0)
    for inv in invoices:
        p_md = float(inv.get("parameters", {}).get("p_md", 5e-5))
        n_th = int(inv.get("parameters", {}).get("n_th", 1))
        for item in inv.get("not_charged", []):
            fee = fees.get(item["geoobject"])
            money += fee or Decimal(0)
            at_risk.append({"vehicle": inv.get("vehicle", ""), "geoobject": item["geoobject"],
                            "entry_utc": item["entry_utc"], "n_inside": item["n_inside"], "n_valid": item["n_valid"],
                            "why": item.get("statuses", {}), "fee": str(fee) if fee is not None else None})  # fmt: skip
        for line in inv["lines"]:
            n = int(line["n_valid_independent"])
            vouched = line.get("vouched_by") or {}  # invoices before sources were recorded: residual tests only
            n_cov = sum(int(k) for source, k in vouched.items() if source not in FAULT_DETECTING)
            need = n_th - n_cov
            bound = 1.0 if need <= 0 else float(stats.binom.sf(need - 1, n - n_cov, p_md))
            charges.append({"vehicle": inv.get("vehicle", ""), "geoobject": line["geoobject"], "entry_utc": line["entry_utc"],
                            "n_valid_independent": n, "vouched_by": vouched, "p_false_bound": bound})  # fmt: skip
    exponent = min((Decimal(inv["total"]).as_tuple().exponent for inv in invoices), default=-2)
    return {"runs": len(invoices), "revenue_at_risk": at_risk, "money_at_risk": str(money.quantize(Decimal(1).scaleb(exponent))),
            "charges": charges}  # fmt: skip


def fee_table(invoices: list[dict]) -> dict[str, Decimal]:
    """The fee each geo-object was charged at in the invoices (the most frequent one)."""
    seen: dict[str, dict[Decimal, int]] = {}
    for inv in invoices:
        for line in inv["lines"]:
            counts = seen.setdefault(line["geoobject"], {})
            fee = Decimal(line["fee"])
            counts[fee] = counts.get(fee, 0) + 1
    return {g: max(c.items(), key=lambda kv: (kv[1], kv[0]))[0] for g, c in seen.items()}
