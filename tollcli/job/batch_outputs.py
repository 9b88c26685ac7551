"""Where each log of a batch writes: its vehicle's folder and its output name (``plan_outputs``), vehicle ids and
names made into safe file names (``path_component``). Used by :mod:`tollcli.job.batch`."""

from __future__ import annotations

import hashlib
import json
import os
from urllib.parse import quote

from tollcli.enforcement.locate import VEHICLE_ID_MAX_CHARS, vehicle_from_log, vehicle_from_path, vehicle_id_problem
from tollcli.errors import UsageError
from tollcli.job.log_files import log_name
from tollcli.job.pipeline import ChargeSettings


def path_component(text: str) -> str:
    """``text`` as one safe file or folder name: percent-encoded, never ``.``/``..`` or hidden, never a path."""
    quoted = quote(text, safe="-_~@+=,")
    if quoted.startswith("."):
        quoted = "%2E" + quoted[1:]
    return quoted or "%00"


def _owner(outdir: str, vehicle: str, name: str) -> str | None:
    """The log (absolute path) whose invoice is at that place in OUTDIR, if any."""
    try:
        with open(os.path.join(outdir, "invoices", vehicle, name + ".json"), encoding="utf-8") as fh:
            log = json.load(fh).get("inputs", {}).get("log")
        return os.path.abspath(log) if isinstance(log, str) else None
    except (OSError, ValueError, AttributeError):
        return None


def vehicle_error(log: str, vehicle: str) -> str:
    problem = vehicle_id_problem(vehicle)
    return f"{log}: {problem} (give each vehicle a printable id of at most {VEHICLE_ID_MAX_CHARS} characters)" if problem else ""


def plan_outputs(logs: list[str], settings: ChargeSettings, outdir: str) -> list[tuple[str, str, str]]:
    """(vehicle id, vehicle folder, output name) of every log: no two logs share an output. A vehicle id that cannot be
    one (:func:`~tollcli.enforcement.locate.vehicle_id_problem`) gets a placeholder folder: that log fails."""
    vehicles = [settings.vehicle or vehicle_from_log(log) or vehicle_from_path(log) for log in logs]
    places = [(path_component(v if vehicle_id_problem(v) is None else f"invalid-vehicle-{hashlib.sha256(v.encode('utf-8', 'surrogateescape')).hexdigest()[:8]}"),
               path_component(log_name(log))) for v, log in zip(vehicles, logs)]  # fmt: skip
    groups: dict[tuple[str, str], list[int]] = {}
    for i, place in enumerate(places):
        groups.setdefault(place, []).append(i)
    names = [name for _, name in places]
    for (folder, name), members in groups.items():
        # the log whose invoice is already there keeps the name; a free name goes to the first log by path
        owner = _owner(outdir, folder, name)
        keeper = next((i for i in members if os.path.abspath(logs[i]) == owner), None)
        if keeper is None and owner is None:
            keeper = min(members, key=lambda i: os.path.abspath(logs[i]))
        for i in members:
            if i != keeper:
                folder_hash = hashlib.sha256(os.path.dirname(os.path.abspath(logs[i])).encode("utf-8", "surrogateescape"))
                names[i] = f"{name}~{folder_hash.hexdigest()[:8]}"
    out = [(v, folder, n) for v, (folder, _), n in zip(vehicles, places, names)]
    seen: dict[tuple[str, str], str] = {}
    for log, (_, folder, n) in zip(logs, out):
        if (folder, n) in seen:  # the same folder twice among the inputs under two spellings
            raise UsageError(f"{log} and {seen[folder, n]} would write the same outputs ({folder}/{n}); give each log once")
        seen[folder, n] = log
    return out
