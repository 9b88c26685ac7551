"""Audit invoices: undercharges and overcharges against the truth, or the risk without it.

With truth (the passages really driven: a list of geo-object ids, each one passage, or a reference trajectory
split into passages, :mod:`truth_passages`):

* each invoice line is paired with one truth passage of its geo-object (by time when both have times);
  undercharge = a passage driven and not charged (missed recognition, MGoR); overcharge = a line that charges
  no passage driven (false recognition, FGoR, or a passage charged twice);
* rates per geo-object with Wilson 95 % intervals, money per run, and the share of invoices whose total is
  within ``invoice_error_pct`` of the true total (ISO/TS 17444-1 style), with its interval. The true total
  prices every passage driven by the tariff at its entry time; when no tariff prices a passage no line
  charged, the run's money is unknown and said so, never counted as 0.

Without truth, a risk report from the invoices alone:

* revenue at risk: passages where fixes fell inside a geo-object but too few valid independent positions
  remained, with the statuses that explain why (not a passage driven on the opposite carriageway);
* per charge, ``p_false_bound``: an upper bound on the chance the charge is false (``P_FALSE_MEANING``):
  P_MD ** n_independent, n_independent the fault-detected positions of its evidence at least
  max(T_c, ``ERROR_CORRELATION_S``) apart — consecutive positions share their errors (30 s: real urban errors
  measured 25 s correlated on the Potsdamer Platz drive); per invoice the union bound over its lines.

Why this file is long: the truth audit, the risk report and what both share (pairing lines with passages, the true
fee, the causes of what was not charged, the findings once each, the clock a relative truth is placed on) read the
same invoices the same way; split, each half would re-read them.
"""

from __future__ import annotations

import math
from decimal import Decimal

import numpy as np
import pandas as pd

from tollcli.charging.truth_passages import (
    is_id_list,
    passages_from_ids,
    truth_passages,
    truth_trajectory,
)
from tollcli.errors import DataError
from tollcli.integrity.sources import FAULT_DETECTING
from tollcli.io.sources import read_json
from tollcli.stats import wilson


def load_invoice(path: str) -> dict:
    doc = read_json(path, "an invoice")
    if not isinstance(doc, dict) or "lines" not in doc or "total" not in doc:
        raise DataError(f"{path}: not a tollcli invoice (no lines/total)")
    return doc


def driven_from_truth(path: str, geo) -> set[str]:
    """Truly driven geo-object ids (each once): see :func:`truth_passages.truth_passages` for the passages."""
    return set(truth_passages(path, geo)["geoobject"])


def start_time_of(invoices: list[dict], names: list[str]) -> str | None:
    """The ``--start-time`` the invoices placed a relative-clock log at (None: none did); DataError when they differ."""
    given = {}
    for invoice, name in zip(invoices, names):
        value = (invoice.get("parameters") or {}).get("start_time") if isinstance(invoice.get("parameters"), dict) else None
        if value is not None:
            given.setdefault(str(value), name)
    if len(given) > 1:
        (a, first), (b, second) = list(given.items())[:2]
        raise DataError(f"{first} places the log at {a}, {second} at {b}: one truth cannot be on both clocks")
    return next(iter(given), None)


def truth_span(path: str, start_time: str | None = None) -> tuple[pd.Timestamp, pd.Timestamp, set[str]] | None:
    """First and last time of a truth trajectory and its vehicle ids (a ``vehicle`` column; empty when none);
    None for an id list or a trajectory without times."""
    if is_id_list(path):
        return None
    try:
        points = truth_trajectory(path, start_time)
    except (DataError, ValueError):
        return None
    times = points["time_utc"].dropna()
    if times.empty:
        return None
    vehicles: set[str] = set()
    if not path.lower().endswith((".parquet", ".geojson", ".json")):
        head = pd.read_csv(path, nrows=0).columns
        if "vehicle" in head:
            vehicles = {str(v) for v in pd.read_csv(path, usecols=["vehicle"])["vehicle"].dropna()}
    return times.min(), times.max(), vehicles


def check_same_trip(invoices: list[dict], names: list[str], truth: str, start_time: str | None = None) -> None:
    """DataError unless every invoice's period overlaps the truth's times (and its vehicle is the truth's, when
    the truth names one): comparing a 2024 invoice with a 2026 drive says nothing."""
    span = truth_span(truth, start_time)
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


#: how far a charged passage's times may lie from the truth's and still be that passage, s (passages of one
#: geo-object are at least the recognition's passage gap apart, so half of it cannot reach the next one)
MATCH_TOLERANCE_S = 60.0
MONEY_UNKNOWN = ("the true fee of a passage no invoice line charged is unknown: give --tariff (and --geo), or keep the "
                 "invoice's tariff and geo-objects where it names them or beside it")  # fmt: skip


def _when(value) -> pd.Timestamp | None:
    try:
        t = pd.Timestamp(value)
    except (TypeError, ValueError):
        return None
    if t is pd.NaT or pd.isna(t):
        return None
    return t.tz_localize("UTC") if t.tzinfo is None else t.tz_convert("UTC")


def match_run(invoice: dict, truth: pd.DataFrame) -> dict:
    """Pair an invoice's lines with the truth's passages of the same geo-object, one to one.

    With times on both sides a line takes the truth passage its entry–exit interval overlaps most (within
    ``MATCH_TOLERANCE_S``); without, lines and passages pair in order. A line of band ``continued`` (charged in
    the vehicle's previous log) pairs like any, and its passage is ``carried``: neither owed nor charged here.
    Returns ``matched`` (line index → truth row), ``carried`` (truth rows), ``under`` (truth rows no line charged),
    ``over`` (line indices that charge no truth passage: a false recognition, or a passage charged twice).
    """
    lines = invoice["lines"]
    matched: dict[int, int] = {}
    gids = truth["geoobject"].to_numpy(object)
    for gid in sorted({str(line["geoobject"]) for line in lines}):
        mine = [k for k, line in enumerate(lines) if str(line["geoobject"]) == gid]
        mine.sort(key=lambda k: (lines[k].get("band") != "continued", k))  # a continued part belongs to the first passage
        free = [int(i) for i in np.flatnonzero(gids == gid)]
        for k in mine:
            if not free:
                break
            a, b = _when(lines[k].get("entry_utc")), _when(lines[k].get("exit_utc"))
            spans = [(_when(truth["entry_utc"].iat[i]), _when(truth["exit_utc"].iat[i])) for i in free]
            if a is not None and all(s is not None for s, _ in spans):
                b = b or a
                tol = pd.Timedelta(seconds=MATCH_TOLERANCE_S)
                overlap = [(min(b, e) - max(a, s)).total_seconds() for s, e in spans]
                best = int(np.argmax(overlap))
                if min(b + tol, spans[best][1] + tol) < max(a, spans[best][0]):  # no passage near its times
                    continue
                matched[k] = free.pop(best)
            else:
                matched[k] = free.pop(0)
    carried = {i for k, i in matched.items() if lines[k].get("band") == "continued"}
    taken = set(matched.values())
    under = [i for i in range(len(truth)) if i not in taken]
    over = [k for k in range(len(lines)) if k not in matched and lines[k].get("band") != "continued"]
    return {"matched": matched, "carried": carried, "under": under, "over": over}


def audit_with_truth(invoices: list[dict], driven, fees: dict[str, Decimal], invoice_error_pct: float = 1.0,
                     pricer=None) -> dict:  # fmt: skip
    """Under/overcharges per passage, per geo-object and per run against the passages really driven.

    ``driven``: the truth's passages (``truth_passages``), or ids (each one passage). The true fee of a passage:
    ``pricer(invoice, geoobject, entry_utc)`` when given (the tariff, at the truth's entry time), else the fee of
    the line that charged it, else ``fees`` (the fee the invoices charged that geo-object at); a passage none of
    these prices makes the run's money unknown (``money_unknown``), never 0.
    """
    truth = driven if isinstance(driven, pd.DataFrame) else passages_from_ids(sorted(driven) if isinstance(driven, set) else driven)
    n = len(invoices)
    runs = [match_run(inv, truth) for inv in invoices]
    per_run, within, known_runs = [], 0, 0
    gid_of = truth["geoobject"].to_numpy(object)
    for inv, run in zip(invoices, runs):
        lines = inv["lines"]
        line_of = {i: k for k, i in run["matched"].items()}

        def true_fee(i: int) -> Decimal | None:
            gid = str(gid_of[i])
            if pricer is not None:
                fee = pricer(inv, gid, _when(truth["entry_utc"].iat[i]))
                if fee is not None:
                    return fee
            if i in line_of and lines[line_of[i]].get("band") != "continued":
                return Decimal(lines[line_of[i]]["fee"])
            return fees.get(gid)

        owed = [i for i in range(len(truth)) if i not in run["carried"]]
        owed_fees = {i: true_fee(i) for i in owed}
        unknown = sorted({str(gid_of[i]) for i, f in owed_fees.items() if f is None})
        true_total = None if unknown else sum(owed_fees.values(), Decimal(0))
        under_fees = [owed_fees[i] for i in run["under"]]
        money_under = None if any(f is None for f in under_fees) else sum(under_fees, Decimal(0))
        money_over = sum((Decimal(lines[k]["fee"]) for k in run["over"]), Decimal(0))
        total = Decimal(inv["total"])
        if true_total is None:
            error_pct = None
        else:
            known_runs += 1
            error_pct = float(abs(total - true_total) / true_total * 100) if true_total else (0.0 if total == 0 else math.inf)
            within += error_pct <= invoice_error_pct
        under = [str(gid_of[i]) for i in run["under"]]
        causes = [{"geoobject": str(gid_of[i]), **undercharge_cause(inv, str(gid_of[i]), truth.iloc[i])} for i in run["under"]]
        entry = [_iso_or_none(truth["entry_utc"].iat[i]) for i in run["under"]]
        per_run.append({
            "vehicle": inv.get("vehicle", ""), "total": str(total), "true_total": _money(true_total),
            "passages_driven": len(owed), "passages_charged": len(lines) - sum(1 for x in lines if x.get("band") == "continued"),
            "undercharged": under, "undercharged_entry_utc": entry, "undercharge_causes": causes,
            "overcharged": [str(lines[k]["geoobject"]) for k in run["over"]],
            "overcharged_entry_utc": [lines[k].get("entry_utc") for k in run["over"]],
            "money_under": _money(money_under), "money_over": str(money_over), "error_pct": error_pct,
            **({"money_unknown": {"geoobjects": unknown, "why": MONEY_UNKNOWN}} if unknown else {}),
        })  # fmt: skip
    per_object = _per_object(invoices, truth, runs)
    low, high = wilson(within, known_runs)
    return {
        "runs": n, "driven": sorted(set(gid_of)), "passages_driven": len(truth),
        "truth_passages": [{"geoobject": str(g), "entry_utc": _iso_or_none(a), "exit_utc": _iso_or_none(b)}
                           for g, a, b in zip(gid_of, truth["entry_utc"], truth["exit_utc"])],
        "geoobjects": per_object, "invoices": per_run,
        "invoice_error_pct": invoice_error_pct, "runs_money_known": known_runs,
        "share_within": within / known_runs if known_runs else None, "share_within_ci95": [low, high],
        "missed_recognitions": sum(o["undercharges"] for o in per_object),
        "false_recognitions": sum(o["overcharges"] for o in per_object),
    }  # fmt: skip


def _per_object(invoices: list[dict], truth: pd.DataFrame, runs: list[dict]) -> list[dict]:
    """Per geo-object: passages driven per run, charged, under- and overcharges with their rates.

    ``rate`` of a driven geo-object: missed passages / passages driven over all runs; of one not driven: the share
    of runs that charged it. ``overcharge_runs``: runs that charged it more often than it was driven."""
    gid_of = truth["geoobject"].to_numpy(object)
    every = sorted(set(map(str, gid_of)).union(str(line["geoobject"]) for inv in invoices for line in inv["lines"]))
    n = len(invoices)
    out = []
    for gid in every:
        p = int(np.sum(gid_of == gid))
        charged = sum(str(line["geoobject"]) == gid and line.get("band") != "continued" for inv in invoices for line in inv["lines"])
        under = sum(sum(str(gid_of[i]) == gid for i in run["under"]) for run in runs)
        over_per_run = [sum(str(inv["lines"][k]["geoobject"]) == gid for k in run["over"]) for inv, run in zip(invoices, runs)]
        over, over_runs = sum(over_per_run), sum(1 for x in over_per_run if x)
        misses, trials = (under, p * n) if p else (over_runs, n)
        low, high = wilson(misses, trials)
        out.append({
            "geoobject": gid, "driven": p > 0, "passages_driven": p, "runs": n, "charged": charged,
            "undercharges": under, "overcharges": over, "overcharge_runs": over_runs,
            "rate": misses / trials if trials else 0.0, "rate_ci95": [low, high],
            "error_kind": "missed recognition" if p else "false recognition",
        })  # fmt: skip
    return out


def _iso_or_none(t) -> str | None:
    t = _when(t)
    return None if t is None else t.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _money(value: Decimal | None) -> str | None:
    return None if value is None else str(value)


def undercharge_cause(invoice: dict, gid: str, passage: pd.Series | None = None) -> dict:
    """Why a driven passage is not on the invoice, from the invoice's own ``not_charged`` evidence (the passages
    of that geo-object it saw near the truth's times, when the truth has times)."""
    n_th = int((invoice.get("parameters") or {}).get("n_th", 1))
    seen = [item for item in invoice.get("not_charged", []) if item["geoobject"] == gid]
    if passage is not None and _when(passage["entry_utc"]) is not None:
        a, b = _when(passage["entry_utc"]), _when(passage["exit_utc"]) or _when(passage["entry_utc"])
        tol = pd.Timedelta(seconds=MATCH_TOLERANCE_S)

        def near(item: dict) -> bool:
            s, e = _when(item.get("entry_utc")), _when(item.get("exit_utc")) or _when(item.get("entry_utc"))
            return s is None or (s <= b + tol and e + tol >= a)

        seen = [item for item in seen if near(item)]
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
    """The tamper/evasion findings the invoices carry, with their vehicle — each once: two invoices of the same log (made
    with other settings, say) carry the same findings, which are one finding about the vehicle."""
    import json

    out, seen = [], set()
    for inv in invoices:
        for item in (inv.get("findings") or {}).get("items", []):
            finding = {"vehicle": inv.get("vehicle", ""), **item}
            key = json.dumps(finding, sort_keys=True, default=str)
            if key not in seen:
                seen.add(key)
                out.append(finding)
    return out


#: the shortest time apart at which two positions' errors count as independent, s: real position errors stay
#: correlated for tens of seconds (1/e time 25 s on the Potsdamer Platz drive, benchmarks/integrity_truth.py;
#: 4 s on the simulator's, whose model has T_c 5 s); the invoice's T_c applies where it is longer
ERROR_CORRELATION_S = 30.0
#: what ``p_false_bound`` bounds, written into the report beside the figures
P_FALSE_MEANING = ("p_false_bound: an upper bound on the probability that this charge is false, i.e. that the vehicle "
                   "did not drive the geo-object although its positions put it there. Were it elsewhere, every one of "
                   "the charge's valid positions would be off by more than HAL (the geo-object is the road buffered by "
                   "HAL, and no other road lies within HAL of it), and each position that a fault-detecting source "
                   "vouched for is so with probability at most P_MD. Consecutive positions share their errors, so only "
                   "positions at least max(T_c, 30 s) apart count as independent (real errors stay correlated for tens "
                   "of seconds: 25 s measured in a city): P(false) <= P_MD ** n_independent. Positions vouched only by "
                   "a covariance (GST) detect no fault and add nothing; with none vouched the bound is 1. More evidence, "
                   "spread over a longer passage, gives a smaller bound.")  # fmt: skip
#: a passage on a carriageway counts as driven the other way (nothing owed) when most positions inside say so
OPPOSITE = "wrong_direction"


def false_charge_bound(n_vouched: int, p_md: float) -> float:
    """Upper bound on P(the charge is false) from its ``n_vouched`` independent fault-detected valid positions."""
    return 1.0 if n_vouched <= 0 else float(p_md) ** int(n_vouched)


def independent_vouched(line: dict, tc_s: float) -> int:
    """The fault-detected positions of a charge's evidence at least max(``tc_s``, ERROR_CORRELATION_S) apart
    (greedily, from the first). A line without evidence times counts one position at most (the caller bounds it
    by the vouched count too)."""
    spacing = max(float(tc_s), ERROR_CORRELATION_S)
    times = []
    for item in line.get("evidence") or []:
        source = item.get("integrity_source") or item.get("test_stat_source") or "none"
        when = pd.to_datetime(item.get("time_utc"), utc=True, errors="coerce")
        if source in FAULT_DETECTING and not pd.isna(when):
            times.append(when.value / 1e9)
    if not times:
        return 1  # the caller takes the smaller of this and the vouched count
    count, last = 0, -math.inf
    for t in sorted(times):
        if t - last >= spacing:
            count, last = count + 1, t
    return count


def on_opposite_carriageway(item: dict) -> bool:
    """Whether a passage that was not charged was driven on the opposite carriageway (most of its positions inside
    travelled against the geo-object's direction): the vehicle owed nothing there."""
    return 2 * int((item.get("statuses") or {}).get(OPPOSITE, 0)) > int(item.get("n_inside", 0))


def risk_report(invoices: list[dict], fees: dict[str, Decimal], pricer=None) -> dict:
    """Revenue at risk and per-charge bounds on a false charge, from invoices alone.

    A not-charged passage whose positions mostly travelled against the carriageway's direction is the other
    carriageway, owed nothing (``opposite_carriageway``), not revenue at risk. Its fee: ``pricer(invoice,
    geoobject, entry_utc)`` (the tariff) when given, else the fee charged for that geo-object elsewhere, else
    unknown (and the money at risk is then a lower bound: ``money_at_risk_complete`` false)."""
    at_risk, opposite, charges, per_invoice = [], [], [], []
    money, complete = Decimal(0), True
    for inv in invoices:
        p_md = float(inv.get("parameters", {}).get("p_md", 5e-5))
        recorded = inv.get("parameters", {})
        tc_s = float(recorded.get("tc_used_s", recorded.get("tc_s", 5.0)))  # a trajectory's correlation time, if longer
        for item in inv.get("not_charged", []):
            row = {"vehicle": inv.get("vehicle", ""), "geoobject": item["geoobject"], "entry_utc": item["entry_utc"],
                   "n_inside": item["n_inside"], "n_valid": item["n_valid"], "why": item.get("statuses", {})}  # fmt: skip
            if on_opposite_carriageway(item):
                opposite.append(row)
                continue
            fee = pricer(inv, item["geoobject"], _when(item["entry_utc"])) if pricer is not None else None
            fee = fee if fee is not None else fees.get(item["geoobject"])
            complete &= fee is not None
            money += fee or Decimal(0)
            at_risk.append({**row, "fee": str(fee) if fee is not None else None})
        bounds = []
        for line in inv["lines"]:
            n = int(line["n_valid_independent"])
            vouched = line.get("vouched_by") or {"pseudorange": n}  # invoices before sources were recorded: residual tests
            n_vouched = sum(int(k) for source, k in vouched.items() if source in FAULT_DETECTING)
            n_independent = min(independent_vouched(line, tc_s), n_vouched)
            bound = false_charge_bound(n_independent, p_md)
            bounds.append(bound)
            charges.append({"vehicle": inv.get("vehicle", ""), "geoobject": line["geoobject"], "entry_utc": line["entry_utc"],
                            "n_valid_independent": n, "vouched_by": vouched, "n_vouched": n_vouched,
                            "n_independent_errors": n_independent, "error_correlation_s": max(tc_s, ERROR_CORRELATION_S),
                            "p_false_bound": bound})  # fmt: skip
        per_invoice.append({"vehicle": inv.get("vehicle", ""), "lines": len(inv["lines"]),
                            "p_any_false_bound": min(1.0, float(sum(bounds)))})  # fmt: skip
    exponent = min((Decimal(inv["total"]).as_tuple().exponent for inv in invoices), default=-2)
    return {"runs": len(invoices), "revenue_at_risk": at_risk, "money_at_risk": str(money.quantize(Decimal(1).scaleb(exponent))),
            "money_at_risk_complete": complete, "opposite_carriageway": opposite, "charges": charges,
            "invoices": per_invoice, "p_false_bound_meaning": P_FALSE_MEANING}  # fmt: skip
