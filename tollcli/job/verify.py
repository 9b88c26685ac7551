"""Verify an invoice: its own content hash, its inputs' hashes, and a byte-for-byte re-run.

Checks, in order, each failing with its own reason:

1. the invoice's ``content_sha256`` matches its content (nobody edited it);
2. every input it names (log, geo-objects, tariff, navigation file) exists and has
   the SHA-256 recorded in the invoice (the inputs are the ones it was made from);
3. processing those inputs again with the recorded parameters gives the same invoice
   (the same canonical text: a re-indented copy of an invoice verifies like the original).
   The re-run reads no cache (no compiled geo-object store, no stored threshold): it recomputes from the
   inputs alone, so an invoice charged with a cache that was altered does not verify (``use_cache``
   opts in for speed, and the summary says so).

Of a file the invoice names, verify says only whether it is the input recorded: it reports nothing of
a file that is not (no digest, no content), since an invoice is untrusted and may name any path.

An input is found where the invoice says (relative to the working directory), else
relative to the invoice's folder, else under its file name beside the invoice: an auditor
who receives the invoice with its files verifies it anywhere. A candidate counts only
when its SHA-256 is the recorded one.
"""

from __future__ import annotations

import json
import os
from contextlib import nullcontext

from tollcli.cache import without_cache
from tollcli.charging.invoice import file_sha256, invoice_json
from tollcli.errors import DataError
from tollcli.io.sources import read_json
from tollcli.charging.invoice import content_sha256
from tollcli.job.pipeline import charge_log, settings_from_invoice

INPUTS = (("log", "log"), ("geoobjects", "geo-objects"), ("tariff", "tariff"), ("nav", "navigation file"), ("roads", "road network"))


class VerifyFailed(DataError):
    """The invoice is not reproduced; the message says why."""


def verify_invoice(path: str, use_cache: bool = False) -> dict:
    """Raise VerifyFailed with the reason, or return a summary of what was checked (``use_cache``: the re-run may
    use the cache, as ``process`` does)."""
    invoice = read_json(path, "an invoice")
    if not isinstance(invoice, dict) or "content_sha256" not in invoice or "inputs" not in invoice:
        raise DataError(f"{path}: not a verifiable tollcli invoice (no content_sha256 or inputs)")
    try:
        recomputed = content_sha256(invoice)
    except ValueError:  # a number beyond a double (1e400): no invoice tollcli writes holds one
        raise DataError(f"{path}: not a verifiable tollcli invoice (a number that is not finite)") from None
    if recomputed != invoice["content_sha256"]:
        raise VerifyFailed(f"{path}: invoice content was modified (content_sha256 does not match its content)")
    inputs = invoice["inputs"]
    if not isinstance(inputs, dict) or not all(isinstance(inputs.get(k), str) for k in ("log", "geoobjects", "tariff")):
        raise DataError(f"{path}: not a verifiable tollcli invoice (inputs must name the log, geo-objects and tariff)")
    found: dict = {}
    for key, label in INPUTS:
        if key not in inputs:
            continue
        file = inputs[key]
        if file == "-":
            raise VerifyFailed(f"{path}: the {label} was read from stdin and cannot be read again")
        if key == "nav" and isinstance(file, list):  # several navigation files, read as one
            digests = inputs.get("nav_sha256")
            digests = digests if isinstance(digests, list) and len(digests) == len(file) else [None] * len(file)
            found[key] = tuple(locate_input(path, str(f), d, label) for f, d in zip(file, digests))
            continue
        # the log is hashed as it is charged (opened once): its digest is checked against the invoice's below
        found[key] = locate_input(path, str(file), inputs.get(f"{key}_sha256"), label, hash_single=key != "log")
    merkle, keys = _osnma_keys(path, inputs)
    with (nullcontext() if use_cache else without_cache()):
        again = _charge_again(path, found, inputs, invoice, merkle, keys)
    recorded_log = inputs.get("log_sha256")
    if again["inputs"].get("log_sha256") != recorded_log:
        raise VerifyFailed(f"{path}: log {found['log']} changed since the invoice was made "
                           f"(its SHA-256 is not the recorded {str(recorded_log)[:12]}…)")  # fmt: skip
    original = invoice_json(invoice)
    fresh = invoice_json(again)
    if fresh != original:
        at = next((i for i, (a, b) in enumerate(zip(fresh, original)) if a != b), min(len(fresh), len(original)))
        line = original.count("\n", 0, at) + 1
        recorded, again_doc = ({k: v for k, v in d.items() if k != "content_sha256"} for d in (invoice, json.loads(fresh)))
        where = first_difference(recorded, again_doc)
        if recorded.get("total") != again_doc.get("total") and not where.startswith("total"):
            where += f"; total: {_short(recorded.get('total'))} in the invoice, {_short(again_doc.get('total'))} again"
        raise VerifyFailed(f"{path}: processing the same inputs again gives a different invoice: {where} "
                           f"(first difference on line {line})")  # fmt: skip
    return {"invoice": path, "content_sha256": invoice["content_sha256"], "inputs": {k: inputs[k] for k, _ in INPUTS if k in inputs},
            "cache": "used" if use_cache else "not used"}  # fmt: skip


def _charge_again(path: str, found: dict, inputs: dict, invoice: dict, merkle, keys) -> dict:
    """The invoice of the inputs found, charged with the invoice's settings. A log that cannot be charged and is not
    the recorded one is reported as changed, without what its content made the reader say."""
    try:
        again, _ = charge_log(found["log"], found["geoobjects"], found["tariff"], settings_from_invoice(invoice), found.get("nav"),
                          found.get("roads"), as_recorded={**{k: inputs[k] for k in found}, **({k: inputs[k] for k in ("osnma_merkle", "osnma_public_keys")} if merkle else {})},
                          osnma_merkle=merkle,
                          osnma_public_keys=keys, osnma_auto=False)  # fmt: skip
    except DataError:
        if file_sha256(found["log"]) != inputs.get("log_sha256"):
            raise VerifyFailed(f"{path}: log {found['log']} changed since the invoice was made "
                               f"(its SHA-256 is not the recorded {str(inputs.get('log_sha256'))[:12]}…)") from None  # fmt: skip
        raise
    return again


def first_difference(recorded, fresh, where: str = "") -> str:
    """Where two JSON documents first differ, as a path with both values (``lines[0].amount: 1.90 recorded, 0.95
    again``)."""
    if isinstance(recorded, dict) and isinstance(fresh, dict):
        for key in sorted(set(recorded) | set(fresh)):
            if key not in recorded or key not in fresh:
                return f"{where}.{key}: {'missing' if key not in recorded else 'present'} in the invoice, {'missing' if key not in fresh else 'present'} again".lstrip(".")
            if recorded[key] != fresh[key]:
                return first_difference(recorded[key], fresh[key], f"{where}.{key}")
    elif isinstance(recorded, list) and isinstance(fresh, list):
        for i, (a, b) in enumerate(zip(recorded, fresh)):
            if a != b:
                return first_difference(a, b, f"{where}[{i}]")
        return f"{where.lstrip('.')}: {len(recorded)} items in the invoice, {len(fresh)} again"
    return f"{where.lstrip('.') or 'the invoice'}: {_short(recorded)} in the invoice, {_short(fresh)} again"


def _short(value) -> str:
    text = json.dumps(value, ensure_ascii=False)
    return text if len(text) <= 80 else text[:77] + "…"


def _osnma_keys(path: str, inputs: dict) -> tuple[str | None, list[str] | None]:
    """The OSNMA key files the invoice names, located like its other inputs (None, None: made without OSNMA)."""
    merkle = inputs.get("osnma_merkle")
    if not isinstance(merkle, str):
        return None, None
    keys, sums = inputs.get("osnma_public_keys") or [], inputs.get("osnma_public_keys_sha256") or []
    if not isinstance(keys, list) or not isinstance(sums, list) or len(keys) != len(sums):
        raise DataError(f"{path}: the invoice's osnma_public_keys and their SHA-256 do not pair up")
    found = locate_input(path, merkle, inputs.get("osnma_merkle_sha256"), "OSNMA Merkle tree")
    return found, [locate_input(path, str(k), s, "OSNMA public key") for k, s in zip(keys, sums)]


def locate_input(invoice_path: str, file: str, recorded, label: str, hash_single: bool = True) -> str:
    """Where the input the invoice names is: the first candidate place whose SHA-256 is the recorded one.

    ``hash_single`` False: a single candidate is returned unhashed (the caller checks its digest as it reads it)."""
    here = os.path.dirname(os.path.abspath(invoice_path))
    candidates = [file] if os.path.isabs(file) else [file, os.path.join(here, file)]
    candidates.append(os.path.join(here, os.path.basename(file)))
    present = [c for c in dict.fromkeys(candidates) if os.path.isfile(c)]
    distinct = {os.path.realpath(c) for c in present}
    if not hash_single and len(distinct) == 1:
        return present[0]
    for candidate in present:
        if file_sha256(candidate) == recorded:
            return candidate
    if not present:
        raise VerifyFailed(f"{invoice_path}: {label} {file} not found (nor beside the invoice)")
    raise VerifyFailed(f"{invoice_path}: {label} {present[0]} changed since the invoice was made "
                       f"(its SHA-256 is not the recorded {str(recorded)[:12]}…)")  # fmt: skip
