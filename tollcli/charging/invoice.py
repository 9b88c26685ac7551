"""Invoices: one line per charged geo-object passage, with fee, times and the evidence behind it.

Shaped after an ISO 17575 charge report: detected charge objects with usage
evidence. Money is Decimal, written as strings; the document carries the tool
version, the input files' SHA-256 and the parameters, and contains no wall-clock
time, so the same inputs give the same bytes.
"""

from __future__ import annotations

import hashlib
import json
from decimal import Decimal

import pandas as pd

from tollcli import __version__
from tollcli.charging.canonical_json import canonical_json
from tollcli.charging.recognition import PASSAGE_GAP_S, GeoObjects
from tollcli.charging.tariffs import Tariff
from tollcli.integrity.raim import STATUS_MEANINGS
from tollcli.integrity.sources import SOURCE_MEANINGS
from tollcli.io.sources import file_sha256  # noqa: F401  (re-exported: batch, verify, pipeline)
from tollcli.times import iso_utc


def _iso(ts) -> str:
    return pd.Timestamp(ts).tz_convert("UTC").strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def build_invoice(charges: pd.DataFrame, positions: pd.DataFrame | None, geo: GeoObjects, tariff: Tariff, *,
                  vehicle: str, vehicle_class: str, inputs: dict[str, str], parameters: dict, period,
                  details: tuple[dict, dict] | None = None, continued: dict | None = None,
                  vehicle_attrs: dict[str, str] | None = None) -> dict:  # fmt: skip
    """The invoice document (a dict of JSON-ready values).

    Per passage: its statuses counted and its independent valid positions listed as
    evidence, each found by one grouping over all positions (no table per passage).
    ``details``: those two already made by :func:`passage_details` (``positions`` is then not used).
    ``continued``: geo-object id → ``{"log", "exit_utc"}`` of a passage the vehicle's previous log charged and
    ended inside; this log's first passage of that geo-object, entered at most ``PASSAGE_GAP_S`` after that
    exit, is the same passage: it is listed (band ``continued``, with its evidence) at fee 0, never charged twice.
    ``vehicle_attrs``: the vehicle's attributes for a tariff of per-km tables (weight class, axles, Euro class…);
    its lines then carry the charged length, the rate per km and per passage, the table and its rows.
    """
    index = {gid: i for i, gid in enumerate(geo.ids)}
    statuses, evidence = details if details is not None else passage_details(positions)
    entry = iso_utc(charges["entry_utc"]) if len(charges) else []
    exit_ = iso_utc(charges["exit_utc"]) if len(charges) else []
    lines, not_charged, total = [], [], Decimal(0)
    zero = Decimal(0).quantize(Decimal(1).scaleb(-tariff.minor_unit))
    carried_in = dict(continued or {})
    vehicle_attributes = {**(vehicle_attrs or {}), "vehicle_class": vehicle_class}
    columns = ("geoobject", "passage", "n_inside", "n_valid", "n_independent", "charged", "entry_utc")
    n_parts = geo.n_parts
    parts_seen = charges["parts_seen"].tolist() if "parts_seen" in charges else [()] * len(charges)
    for k, (gid, passage, n_inside, n_valid, n_indep, charged, entry_utc) in enumerate(zip(*(charges[c] for c in columns))):
        i = index[gid]
        base = {
            "geoobject": gid, "name": geo.names[i], "road_class": geo.road_class[i], "hal_m": float(geo.hal_m[i]),
            "entry_utc": entry[k], "exit_utc": exit_[k], "n_inside": int(n_inside),
            "n_valid": int(n_valid), "n_valid_independent": int(n_indep),
            "statuses": statuses[(gid, passage)],
        }  # fmt: skip
        if geo.environment is not None and geo.environment[i]:  # the operator's declaration the model level took
            base["environment"] = str(geo.environment[i])
        if n_parts[i] > 1:  # a section cut around other roads: the parts (geo-objects) of it that saw the passage
            base["parts_seen"] = list(parts_seen[k])
        if not charged:
            not_charged.append(base)
            continue
        carried = carried_in.pop(gid, None)
        if carried is not None and continues(carried["exit_utc"], entry_utc):
            lines.append({**base, "fee": str(zero), "band": "continued", "continues": carried,
                          "evidence": evidence.get((gid, passage), [])})  # fmt: skip
            continue
        length_m = float(geo.length_m[i]) if geo.length_m is not None else None
        price = tariff.price(gid, geo.road_class[i], length_m, vehicle_attributes, pd.Timestamp(entry_utc).to_pydatetime())
        total += price.fee
        lines.append({**base, "fee": str(price.fee), "band": price.band, **_rate_fields(price),
                      "evidence": evidence.get((gid, passage), [])})  # fmt: skip
    for line in lines:  # the sources whose verdicts made its positions count (the audit bounds a false charge with them)
        line["vouched_by"] = vouched_by(line["evidence"])
        checks = evidence_checks(line["evidence"])
        if checks is not None:  # the checks that confirmed its evidence, and why the others did not check
            line["checks"] = checks
    doc = {
        "tool": f"tollcli {__version__}",
        "vehicle": vehicle,
        "vehicle_class": vehicle_class,
        **({"vehicle_attributes": dict(sorted(vehicle_attrs.items()))} if vehicle_attrs else {}),
        "currency": tariff.currency,
        "period": {"start_utc": _iso(period[0]), "end_utc": _iso(period[1])} if period else None,
        "inputs": inputs,
        "parameters": parameters,
        "lines": lines,
        "total": str(total.quantize(Decimal(1).scaleb(-tariff.minor_unit))),
        "not_charged": not_charged,
    }
    sources = {source for line in lines for source in line["vouched_by"]}
    if sources - {"grs", "pseudorange"}:  # the auditor reads what a receiver's own verdict is worth
        doc["source_notes"] = {s: SOURCE_MEANINGS[s] for s in sorted(sources) if s in SOURCE_MEANINGS}
    seen = {status for passage in (*lines, *not_charged) for status in passage["statuses"]}
    if "probable_false_alarm" in seen:  # the auditor reads why so many positions alarmed, and what it does not mean
        doc["status_notes"] = {"probable_false_alarm": STATUS_MEANINGS["probable_false_alarm"]
                               + f" (p_fa = {parameters.get('p_fa')}; see each position's p_fa in the evidence)"}  # fmt: skip
    if parameters.get("raim") == "ss":  # the default RAIM's verdicts, in the words the summary line quotes
        notes = {k: SEPARATION_NOTES[k] for k in ("unavailable", "fault_detected") if k in seen}
        if notes:
            doc["status_notes"] = {**doc.get("status_notes", {}), **notes}
    if parameters.get("integrity_sources_used") == "model" and "unavailable" in seen:  # the log's only evidence
        declared = parameters.get("environment", "auto")
        doc["status_notes"] = {**doc.get("status_notes", {}), "unavailable": MODEL_UNAVAILABLE.format(
            environment=MODEL_ENVIRONMENT.get(declared, f"environment {declared}"))}  # fmt: skip
    return doc


#: why a log at the ``model`` level (satellites or HDOP, no integrity output) was not charged; {environment} is the
#: sentence of :data:`MODEL_ENVIRONMENT` for the environment the user declared (or auto)
MODEL_UNAVAILABLE = (
    "the receiver reports no integrity output (no GRS, GBS or GST, no pseudorange residuals): only the satellites' "
    "geometry bounds its positions, and under the error model assumed here ({environment}) the protection level "
    "exceeds the geo-object's HAL. Such a bound detects no fault; a receiver that writes GRS, GBS or GST (or u-blox "
    "NAV-SAT with prRes) is charged on its own evidence"
)
#: the error model the ``model`` level assumed, by the declared ``--environment``
MODEL_ENVIRONMENT = {
    "auto": ("environment auto: the urban σ, since no residual measured the environment, except where the receiver "
             "reported a corrected fix (DGNSS/SBAS, RTK: the corrected σ); --environment open declares open country"),
    "open": "environment open, as declared: the nominal σ (the corrected σ for a corrected fix)",
    "urban": "environment urban, as declared: the urban σ on every epoch",
}


#: what the solution-separation RAIM's denials mean (first sentence: the process summary's reason)
SEPARATION_NOTES = {
    "unavailable": (
        "the protection level exceeds the geo-object's HAL for this receiver here. The solution separation bounds "
        "the position over every satellite that may have failed and over the noise; few satellites, a weak geometry "
        "or a street canyon (environment 'urban': the residuals of the last 30 s exceed the error model 1.5-fold, "
        "so each satellite's σ is tens of metres, from its C/N0) make it larger than the HAL, and the position "
        "cannot be vouched for; each position's hpl_m is in the epoch table (tollcli integrity)"
    ),
    "fault_detected": (
        "a satellite disagrees with the others: leaving one out moves the position further than its threshold "
        "allows (separation_ratio > 1 at P_FA = p_fa) — a credible alarm; the position is not charged on"
    ),
}


#: a status's reason in a user's words, where the invoice's notes have none of their own
WHY_NOT = {
    "unmonitored": "no integrity source in the log (no GRS, GBS or GST sentences, or no satellites at all): "
                   "the positions could not be checked",
    "insufficient": "too few satellites for a check (no more than the unknowns)",
    "unavailable": "the protection level exceeds the geo-object's HAL for this receiver here",
    "fault_detected": "a satellite disagreed with the others (a detected fault)",
    "probable_false_alarm": "the RAIM test failed (the papers' ETC at a HAL this small fails often without a fault)",
    "wrong_direction": "the vehicle drove against this carriageway's direction: the other carriageway",
    "valid_outside": "the position the integrity check vouched for (its own solution, after any exclusion) lies "
                     "outside the geo-object, though the receiver's lies inside",
    "direction_unknown": "no course or too slow to tell the direction on this carriageway",
    "speed_inconsistent": "the positions were not where the reported (Doppler) velocity took them (a fault)",
    "mm_off_road": "the position jumped off the road the vehicle was matched to (a fault)",
    "mm_other_road": "map matching put the vehicle on another road, beyond the position's bound from this one",
}  # fmt: skip


def explain_not_charged(invoice: dict) -> None:
    """Give each passage not charged its ``why``: the commonest reason its positions did not count, in words (the
    invoice's own ``status_notes`` first, first sentence; else :data:`WHY_NOT`), with how many positions it held."""
    notes = invoice.get("status_notes") or {}
    for passage in invoice.get("not_charged", []):
        failing = {k: int(n) for k, n in passage.get("statuses", {}).items() if k not in ("valid", "excluded_valid")}
        if not failing:
            passage["why"] = f"fewer valid independent positions than N_Th ({invoice.get('parameters', {}).get('n_th', 1)})"
            continue
        top = max(sorted(failing), key=failing.get)
        words = notes[top].split(". ")[0] if top in notes else WHY_NOT.get(top, top)
        passage["why"] = f"{words} ({top}: {failing[top]} of {passage.get('n_inside', sum(failing.values()))} positions)"
        if passage.get("environment") and invoice.get("parameters", {}).get("integrity_sources_used") == "model":
            passage["why"] += (f"; its road is declared {passage['environment']} by the operator: the "
                               f"{'nominal' if passage['environment'] == 'open' else 'urban'} σ there")  # fmt: skip


def _rate_fields(price) -> dict:
    """An invoice line's pricing beyond fee and band: for per-km tables, what was charged for and at which rate."""
    if not price.table:
        return {}
    return {"tariff_table": price.table, "length_km": None if price.length_km is None else str(price.length_km),
            "rate_per_km": str(price.per_km), "rate_per_passage": str(price.per_passage), "rates": price.components}  # fmt: skip


def continues(exit_utc: str, entry_utc) -> bool:
    """Whether a passage entered at ``entry_utc`` continues one left at ``exit_utc`` (the passages' own gap rule)."""
    gap_s = (pd.Timestamp(entry_utc) - pd.Timestamp(exit_utc)).total_seconds()
    return 0 <= gap_s <= PASSAGE_GAP_S


def passage_details(positions: pd.DataFrame) -> tuple[dict, dict]:
    """(geo-object, passage) → statuses counted, and → evidence (the independent valid positions)."""
    return _statuses(positions), _evidence(positions)


def _statuses(positions: pd.DataFrame) -> dict[tuple, dict[str, int]]:
    """(geo-object, passage) → {status: positions} (the policy's verdict where there is one)."""
    if positions.empty:
        return {}
    column = "verdict" if "verdict" in positions else "raim_status"
    counts = positions.groupby(["geoobject", "passage", column], sort=True).size()
    out: dict[tuple, dict[str, int]] = {}
    for (gid, passage, status), n in zip(counts.index, counts.to_numpy().tolist()):
        out.setdefault((gid, passage), {})[str(status)] = n
    return out


def _evidence(positions: pd.DataFrame) -> dict[tuple, list[dict]]:
    """(geo-object, passage) → its independent valid positions, in the positions' order."""
    if positions.empty:
        return {}
    kept = positions[positions["independent"].to_numpy(bool)]
    times = iso_utc(kept["time_utc"]) if len(kept) else []
    out: dict[tuple, list[dict]] = {}
    # ten significant digits: the figures an auditor reads, and the same whichever chunks the log was read in (a
    # batch's padding changes the last bits of a float)
    numbers = [[None if v != v else float(f"{v:.10g}") for v in kept[c].to_numpy(float).tolist()] if c in kept else [None] * len(kept)
               for c in ("test_stat", "threshold", "p_fa", "hpl_m", "separation_ratio")]  # fmt: skip
    vouching = kept["integrity_source"] if "integrity_source" in kept else kept["test_stat_source"]
    nav_auth = kept["nav_auth"].tolist() if "nav_auth" in kept else [None] * len(kept)
    checked = "confirmed_by" in kept
    confirmed = kept["confirmed_by"].tolist() if checked else [None] * len(kept)
    unchecked = kept["not_checked"].tolist() if checked else [None] * len(kept)
    for gid, passage, epoch, when, status, stat, threshold, p_fa, hpl, ratio, source, vouched, authenticated, by, not_by in zip(
        kept["geoobject"], kept["passage"].tolist(), kept["epoch_row"].tolist(), times, kept["raim_status"],
        *numbers, kept["test_stat_source"], vouching, nav_auth, confirmed, unchecked,
    ):  # fmt: skip
        item = {"epoch": epoch, "time_utc": when, "raim_status": status, "test_stat": stat, "threshold": threshold,
                "p_fa": p_fa, "test_stat_source": source, "integrity_source": vouched}  # fmt: skip
        if ratio is not None:  # solution separation: the bound it was declared against and its largest separation
            item.update(hpl_m=hpl, separation_ratio=ratio)
        if authenticated is not None:  # the log was checked for authenticated navigation data (OSNMA)
            item["nav_auth"] = authenticated
        if checked:  # the policy's checks: which confirmed the position, and why the others did not check
            item["confirmed_by"] = [c for c in str(by).split("+") if c]
            item["not_checked"] = [c for c in str(not_by).split("+") if c]
        out.setdefault((gid, passage), []).append(item)
    return out


def evidence_checks(evidence: list[dict]) -> dict[str, dict[str, int]] | None:
    """The policy's checks over a line's evidence: {``confirmed``: check → positions it confirmed, ``not_checked``:
    why → positions} (None when no check ran: the RAIM alone)."""
    if not evidence or "confirmed_by" not in evidence[0]:
        return None
    confirmed: dict[str, int] = {}
    not_checked: dict[str, int] = {}
    for item in evidence:
        for c in item["confirmed_by"]:
            confirmed[c] = confirmed.get(c, 0) + 1
        for c in item["not_checked"]:
            not_checked[c] = not_checked.get(c, 0) + 1
    return {"confirmed": dict(sorted(confirmed.items())), "not_checked": dict(sorted(not_checked.items()))}


def vouched_by(evidence: list[dict]) -> dict[str, int]:
    """Source → the number of evidence positions its verdict made count."""
    out: dict[str, int] = {}
    for item in evidence:
        source = item.get("integrity_source") or item.get("test_stat_source") or "none"
        out[source] = out.get(source, 0) + 1
    return dict(sorted(out.items()))


def invoice_json(invoice: dict) -> str:
    """The invoice's canonical text: JSON, keys sorted, two-space indent (a sealed invoice's is kept)."""
    if isinstance(invoice, SealedInvoice) and invoice.text is not None:
        return invoice.text
    return canonical_json(invoice) + "\n"  # = json.dumps(invoice, indent=2, sort_keys=True, ensure_ascii=False)


class SealedInvoice(dict):
    """An invoice with its ``content_sha256`` and its canonical text, encoded once (JSON with an indent is slow).

    Setting or removing a top-level key drops the kept text; do not change nested values.
    """

    text: str | None = None

    def __setitem__(self, key, value):
        self.text = None
        super().__setitem__(key, value)

    def __delitem__(self, key):
        self.text = None
        super().__delitem__(key)


def _sealed_body(invoice: dict) -> tuple[dict, str, str]:
    """The invoice without ``content_sha256``, its canonical text and that text's SHA-256: the one sealing recipe."""
    body = {k: v for k, v in invoice.items() if k != "content_sha256"}
    text = invoice_json(body)
    return body, text, hashlib.sha256(text.encode("utf-8")).hexdigest()


def content_sha256(invoice: dict) -> str:
    """SHA-256 of the invoice's canonical JSON without its own ``content_sha256`` (what :func:`seal` writes there)."""
    return _sealed_body(invoice)[2]


def seal(invoice: dict) -> SealedInvoice:
    """The invoice with ``content_sha256`` = SHA-256 of its canonical text without that key.

    The sealed text is the body's text with the hash line put first, where sorting puts
    ``content_sha256`` (checked; otherwise it is encoded again).
    """
    body, text, digest = _sealed_body(invoice)
    sealed = SealedInvoice(body)
    dict.__setitem__(sealed, "content_sha256", digest)
    if body and min(body) > "content_sha256" and text.startswith('{\n  "'):
        sealed.text = '{\n  "content_sha256": ' + json.dumps(digest) + ",\n" + text[2:]
    return sealed


def invoice_csv(invoice: dict) -> str:
    """The invoice lines as CSV: one row per charged passage, each with its vehicle, log and currency.

    A table of passages only — no total row among them (the total is the invoice's, in its JSON and on stderr):
    CSVs of many invoices concatenate into one table, and a spreadsheet's sum of ``fee`` is the total.
    """
    import csv
    import io

    cols = ["vehicle", "log", "geoobject", "name", "road_class", "entry_utc", "exit_utc", "n_valid_independent", "band", "fee", "currency"]
    if invoice.get("scheme") == "city":  # gantry crossings and zone presences: the fee before the rules, and after them
        cols = ["vehicle", "log", "kind", "geoobject", "name", "direction", "time_utc", "time_local", "rate", "fee", "charged", "currency"]
    if any("tariff_table" in line for line in invoice["lines"]):  # per-km tables: what each fee was charged for
        cols[-2:-2] = ["tariff_table", "length_km", "rate_per_km", "rate_per_passage"]
    common = {"vehicle": invoice.get("vehicle"), "log": (invoice.get("inputs") or {}).get("log"), "currency": invoice.get("currency")}
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(cols)
    for line in invoice["lines"]:
        row = {**line, **common}
        writer.writerow(["" if row.get(c) is None else row.get(c) for c in cols])
    return buf.getvalue()
