"""Read gpsd's regression output (``*.log.chk``) for comparison with our reader.

A ``.chk`` file repeats each input sentence followed by the JSON reports gpsd
produced from it. We keep the TPV reports that follow a standard NMEA sentence
(``$`` + two-letter talker): gpsd also emits TPVs after proprietary sentences
(e.g. Ericsson ``$PERC,GPavp``, a timing receiver's averaged survey position)
and binary packets, which are not NMEA 0183 fixes.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

#: gpsd "corrects" GPS week rollover by adding 1024-week multiples when a log's
#: date is older than its build date allows (2015 → 2034); match modulo that.
WEEK_ROLLOVER_MS = 1024 * 7 * 86_400_000
_STANDARD_SENTENCE = re.compile(r"^\$[A-OQ-Z][A-Z][A-Z]{3},")


def rollover_key(t: np.datetime64) -> int:
    """A time as ms modulo 1024 GPS weeks."""
    return int(t.astype("datetime64[ms]").astype(np.int64)) % WEEK_ROLLOVER_MS


def gpsd_fixes(chk: Path) -> dict[int, tuple[float, float]]:
    """rollover_key(time) → (lat, lon) of gpsd's last TPV for that time after a standard sentence."""
    fixes: dict[int, tuple[float, float]] = {}
    after_standard = False
    for line in chk.read_text(encoding="latin-1").splitlines():
        if not line.startswith("{"):
            after_standard = bool(_STANDARD_SENTENCE.match(line))
            continue
        if not (after_standard and line.startswith('{"class":"TPV"')):
            continue
        try:
            tpv = json.loads(line)
        except json.JSONDecodeError:
            continue
        if "time" in tpv and "lat" in tpv and "lon" in tpv and tpv.get("mode", 0) >= 2:
            key = rollover_key(np.datetime64(tpv["time"].rstrip("Z"), "ms"))
            fixes[key] = (float(tpv["lat"]), float(tpv["lon"]))
    return fixes


def our_fixes(epochs) -> dict[int, tuple[float, float]]:
    """The same mapping from our epoch table (dated epochs with a position)."""
    ep = epochs.dropna(subset=["lat_deg", "lon_deg", "time_utc"])
    times = ep["time_utc"].dt.tz_convert(None).to_numpy().astype("datetime64[ms]")
    return {rollover_key(t): (la, lo) for t, la, lo in zip(times, ep["lat_deg"], ep["lon_deg"])}
