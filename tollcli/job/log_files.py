"""Which files are receiver logs, and their names: from paths, globs, folders and ``@lists``; which are pseudorange logs."""

from __future__ import annotations

import glob
import os

from tollcli.errors import TollError, UsageError
from tollcli.io.sources import looks_like_log

LOG_SUFFIXES = (".nmea", ".nmea.gz", ".log", ".log.gz", ".txt", ".gz", ".csv", ".ubx", ".obs", ".rnx", ".pos")
#: suffixes only a receiver log has: a folder's file with one is always taken (a broken one fails, said);
#: a .txt, .log, .csv or .gz is taken when its first bytes are a log's (``looks_like_log``)
LOG_ONLY_SUFFIXES = (".nmea", ".nmea.gz", ".ubx", ".obs", ".rnx", ".pos")


def log_name(log: str) -> str:
    """The log's file name without its log suffix (``truck1.day2.nmea.gz`` → ``truck1.day2``)."""
    base = os.path.basename(log)
    for suffix in sorted(LOG_SUFFIXES, key=len, reverse=True):
        if base.lower().endswith(suffix) and len(base) > len(suffix):
            return base[: -len(suffix)]
    return base


def expand_inputs(inputs: list[str], passed_over: list[str] | None = None) -> list[str]:
    """Logs from paths, globs, directories (their log files) and list files (``@list.txt``: one path per line).

    In a directory a file is a log when its suffix is one only logs have (``LOG_ONLY_SUFFIXES``), or a log's
    suffix and its first bytes are a log's (``looks_like_log``); the others (a ``notes.txt``) are appended to
    ``passed_over``. Files named, listed or globbed are all taken."""
    found: list[str] = []
    for item in inputs:
        if item.startswith("@"):
            try:
                with open(item[1:], encoding="utf-8") as fh:
                    found += [ln.strip() for ln in fh if ln.strip() and not ln.startswith("#")]
            except OSError as exc:
                raise UsageError(f"{item[1:]}: cannot read the list of logs ({exc.strerror})") from None
        elif os.path.isdir(item):
            for p in sorted(glob.glob(os.path.join(glob.escape(item), "**", "*"), recursive=True)):
                if not os.path.isfile(p):
                    continue
                if p.lower().endswith(LOG_ONLY_SUFFIXES) or (p.lower().endswith(LOG_SUFFIXES) and looks_like_log(p)):
                    found.append(p)
                elif passed_over is not None:
                    passed_over.append(os.path.normpath(p))
        elif any(ch in item for ch in "*?["):
            found += [p for p in glob.glob(item, recursive=True) if os.path.isfile(p)]
        else:
            found.append(item)
    logs = sorted(dict.fromkeys(os.path.normpath(p) for p in found))
    if not logs:
        raise UsageError("no logs found in " + " ".join(inputs))
    return logs


def is_pseudorange_log(log: str, input_format: str) -> bool:
    """Whether ``log`` is a pseudorange log (its head read when its format is ``auto``; an unreadable one: no)."""
    from tollcli.io.sources import sniff_format
    from tollcli.readers.navigation import NAVIGATION_KINDS

    try:
        kind = sniff_format(log) if input_format == "auto" else input_format
    except (OSError, TollError):
        return False
    return kind not in NAVIGATION_KINDS
