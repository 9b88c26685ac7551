"""Verify an invoice: its own content hash, its inputs' hashes, and a byte-for-byte re-run.

Checks, in order, each failing with its own reason:

1. the invoice's ``content_sha256`` matches its content (nobody edited it);
2. every input it names (log, geo-objects, tariff, navigation file) exists and has
   the SHA-256 recorded in the invoice (the inputs are the ones it was made from);
3. processing those inputs again with the recorded parameters gives the same bytes.
"""

from __future__ import annotations

import os

from tollcli.charging.invoice import file_sha256, invoice_json
from tollcli.errors import DataError
from tollcli.io.sources import read_json
from tollcli.job.pipeline import charge_log, content_sha256, settings_from_invoice

INPUTS = (("log", "log"), ("geoobjects", "geo-objects"), ("tariff", "tariff"), ("nav", "navigation file"), ("roads", "road network"))


class VerifyFailed(DataError):
    """The invoice is not reproduced; the message says why."""


def verify_invoice(path: str) -> dict:
    """Raise VerifyFailed with the reason, or return a summary of what was checked."""
    invoice = read_json(path, "an invoice")
    if not isinstance(invoice, dict) or "content_sha256" not in invoice or "inputs" not in invoice:
        raise DataError(f"{path}: not a verifiable tollcli invoice (no content_sha256 or inputs)")
    if content_sha256(invoice) != invoice["content_sha256"]:
        raise VerifyFailed(f"{path}: invoice content was modified (content_sha256 does not match its content)")
    inputs = invoice["inputs"]
    for key, label in INPUTS:
        if key not in inputs:
            continue
        file = inputs[key]
        if file == "-":
            raise VerifyFailed(f"{path}: the {label} was read from stdin and cannot be read again")
        if not os.path.isfile(file):
            raise VerifyFailed(f"{path}: {label} {file} not found")
        recorded = inputs.get(f"{key}_sha256")
        actual = file_sha256(file)
        if recorded != actual:
            raise VerifyFailed(f"{path}: {label} {file} changed since the invoice was made "
                               f"(sha256 {actual[:12]}… ≠ recorded {str(recorded)[:12]}…)")  # fmt: skip
    again, _ = charge_log(inputs["log"], inputs["geoobjects"], inputs["tariff"], settings_from_invoice(invoice), inputs.get("nav"),
                          inputs.get("roads"))  # fmt: skip
    with open(path, encoding="utf-8") as fh:
        original = fh.read()
    fresh = invoice_json(again)
    if fresh != original:
        at = next((i for i, (a, b) in enumerate(zip(fresh, original)) if a != b), min(len(fresh), len(original)))
        line = original.count("\n", 0, at) + 1
        raise VerifyFailed(f"{path}: processing the same inputs again gives a different invoice (first difference on line {line})")
    return {"invoice": path, "content_sha256": invoice["content_sha256"], "inputs": {k: inputs[k] for k, _ in INPUTS if k in inputs}}
