"""gpsd JSON (``gpspipe -w``, ``gpsdecode``, gpsd's regression ``.chk`` files) → the epoch and satellite tables.

gpsd decodes every receiver protocol it knows (NMEA, u-blox, SiRF, Trimble TSIP, Javad GREIS, Garmin, …) into one
JSON report stream; reading it brings all of them to the integrity checks:

* ``TPV`` (time-position-velocity): ``time``, ``mode`` (1 no fix, 2 2-D, 3 3-D), ``status`` (2 DGPS, 3 RTK fixed,
  4 RTK float, 5 dead reckoning, …), ``lat``/``lon``, ``altMSL`` (or ``alt``), ``geoidSep``, ``speed`` (m/s),
  ``track`` (degrees). Several TPVs with the same time (gpsd reports as the receiver's sentences arrive) are one
  epoch, later fields filling the earlier, also when gpsd re-reports a fix of a second before from another of the
  receiver's messages (SiRF): the epochs of the last ``REREPORT_S`` seconds stay open. gpsd's ``eph``/``epx``/``epy`` are its own estimates ("certainty
  unknown" in its documentation): not read as a bound;
* ``SKY``: per satellite ``gnssid``/``svid`` (else ``PRN``), ``el``, ``az``, ``ss`` (C/N0, dB-Hz), ``used`` and,
  where the receiver gives it (u-blox NAV-SAT/NAV-SVINFO), ``prRes`` — the pseudorange residual (m), read as a
  GRS residual; ``hdop``/``vdop``/``pdop``;
* ``GST``: the receiver's pseudorange error statistics (``rms``, ``major``, ``minor``, ``orient``, ``lat``,
  ``lon``, ``alt``), as NMEA GST.

A SKY or GST belongs to the TPV of the same ``time``; one that comes before a TPV, to that TPV when it is at most
``SKY_MAX_AGE_S`` older or has no time (receivers time their satellite reports on their own: Trimble's come
between fixes). An epoch without a SKY of its own takes the latest SKY of at most
``SKY_MAX_AGE_S`` earlier: receivers report satellites less often than fixes. Lines that are not JSON (NMEA
echoed in a ``.chk``, gpsd's ``#`` comments) are another protocol on the stream, counted as unused; a line that
starts as JSON and does not parse, or a report without its ``class``, is malformed: skipped and counted, an error
with ``--strict``. A TPV without a ``time`` (before a first fix; a Quectel EG25 reports its fixes so) is no epoch: skipped
and counted (``untimed_reports``), never an epoch that asks for ``--date``.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from functools import lru_cache
from typing import BinaryIO

import numpy as np

from tollcli.readers.nav_tables import TableBuilder, skip_malformed, text_line_blocks
from tollcli.readers.nmea.line_reader import ReadStats
from tollcli.readers.nmea.reader import CHUNK_EPOCHS, NmeaTables
from tollcli.readers.nmea.satellite_ids import by_number
from tollcli.times import PLAUSIBLE_MS

#: gpsd gnssid → constellation
GNSS_NAME = {0: "GPS", 1: "SBAS", 2: "Galileo", 3: "BeiDou", 5: "QZSS", 6: "GLONASS", 7: "NavIC"}
SKY_MAX_AGE_S = 5.0
#: a TPV at most this much older than the latest epoch re-reports a fix (s); further back, the clock jumped
REREPORT_S = 2.0
#: TPVs this close in time (ms) report the same fix (a receiver's messages time it a millisecond apart)
SAME_FIX_MS = 50
#: TPV status → GGA quality
_QUALITY = {2: 2, 3: 4, 4: 5, 5: 6}


#: the types a number of ``json.loads`` has (a bool is not one)
_NUMBERS = (float, int)


def _float(report: dict, *names: str) -> float:
    """The first of ``names`` that is a number, as a float (NaN: none is; a report with an integer too large for one
    was skipped as malformed as it was decoded: :data:`_DECODER`)."""
    for name in names:
        value = report.get(name)
        if type(value) in _NUMBERS:
            return float(value)
    return math.nan


def _number(value) -> float:
    """A JSON value as a float when it is a number (NaN otherwise: text, a bool, null, missing)."""
    return float(value) if type(value) in _NUMBERS else math.nan


def _small_int(value) -> int | None:
    """``value`` if it is an integer an id or a count can be (|value| < 2³¹), else None (a bool is not one)."""
    return value if type(value) is int and -(2**31) < value < 2**31 else None


def _time_ms(text) -> int | None:
    """Milliseconds since 1970 of a report's ISO time (None: no time, or not one in 1980–2200)."""
    if not isinstance(text, str) or len(text) < 19:
        return None
    return _parsed_ms(text)


@lru_cache(maxsize=256)  # a cycle's TPV, SKY and GST carry one time: parsed once
def _parsed_ms(text: str) -> int | None:
    try:
        ms = int(np.datetime64(text.rstrip("Z"), "ms").astype(np.int64))
    except (ValueError, OverflowError):
        return None
    return ms if PLAUSIBLE_MS[0] <= ms < PLAUSIBLE_MS[1] else None


class _TooLarge(ValueError):
    """An integer in a report beyond 64 bits: no receiver writes one."""


def _checked_int(text: str) -> int:
    """A JSON integer, refused (:class:`_TooLarge`) beyond 64 bits."""
    value = int(text)
    if not -(2**63) <= value < 2**63:
        raise _TooLarge(text[:30])
    return value


#: the reports' decoder: every integer checked as it is read (``json.loads`` with a decoder made once)
_DECODER = json.JSONDecoder(parse_int=_checked_int)
#: why a report with an integer beyond 64 bits is skipped
TOO_LARGE = "a number too large for any field"


def _damaged(report) -> str:
    """Why a report cannot be a receiver's ('' when it can): a time outside 1980–2200 (an integer too large for 64
    bits anywhere in it is refused as it is read: :data:`_DECODER`)."""
    text = report.get("time") if isinstance(report, dict) else None
    if isinstance(text, str) and len(text) >= 19 and _time_ms(text) is None:
        try:
            np.datetime64(text.rstrip("Z"), "ms")
        except (ValueError, OverflowError):
            return ""  # not a time at all: the report is used without one, as before
        return f"a time outside 1980–2200 ({text[:30]})"
    return ""


def _tpv_fields(r: dict) -> dict:
    mode = _small_int(r.get("mode")) or 0
    status = _small_int(r.get("status"))
    status = 1 if status is None else status
    valid = mode >= 2 and status not in (5, 8)  # dead reckoning only, simulated: no GNSS fix; 7: a surveyed position
    quality = _QUALITY.get(status, 1) if mode >= 2 else 6 if status == 5 else 0
    fields = {"fix_mode": mode if mode in (1, 2, 3) else -1, "fix_valid": valid, "fix_quality": quality,
              "mode_indicator": "D" if status == 2 else "E" if status == 5 else "A" if valid else "N"}  # fmt: skip
    lat, lon = _float(r, "lat"), _float(r, "lon")
    if mode >= 2 and math.isfinite(lat) and math.isfinite(lon):
        fields.update(lat_deg=lat, lon_deg=lon)
    for column, names in (("alt_m", ("altMSL", "alt")), ("geoid_sep_m", ("geoidSep",)), ("speed_mps", ("speed",)),
                          ("course_deg", ("track",))):  # fmt: skip
        value = _float(r, *names)
        if math.isfinite(value):
            fields[column] = value
    return fields


def _sky_satellites(r: dict) -> list[tuple]:
    out = []
    for s in r.get("satellites") or ():
        if type(s) is not dict:
            continue
        get = s.get
        gnss, svid, prn = _small_int(get("gnssid")), _small_int(get("svid")), _small_int(get("PRN"))
        if gnss is not None and svid is not None:
            name = GNSS_NAME.get(gnss, "unknown")
        elif prn is not None:
            name, svid = by_number(prn)
        else:
            continue
        el, az, ss = _number(get("el")), _number(get("az")), _number(get("ss"))
        used = get("used") is True
        residual = _number(get("prRes")) if used else math.nan
        known = math.isfinite(el) and -90 <= el <= 90 and math.isfinite(az)
        out.append((name, int(svid), el if known else math.nan, az % 360.0 if known else math.nan,
                    ss if ss > 0 else math.nan, used, residual, prn if prn is not None else -1))  # fmt: skip
    return out


def _sky_fields(r: dict) -> dict:
    return {k: v for k, v in (("hdop", _float(r, "hdop")), ("vdop", _float(r, "vdop")), ("pdop", _float(r, "pdop")))
            if math.isfinite(v)}  # fmt: skip


def _gst_fields(r: dict) -> dict:
    names = {"rms_residual_m": "rms", "sigma_major_m": "major", "sigma_minor_m": "minor", "ellipse_orient_deg": "orient",
             "sigma_lat_m": "lat", "sigma_lon_m": "lon", "sigma_alt_m": "alt"}  # fmt: skip
    return {k: v for k, v in ((k, _float(r, n)) for k, n in names.items()) if math.isfinite(v)}


def iter_gpsd_json_tables(source: str | os.PathLike | BinaryIO, *, strict: bool = False, stats: ReadStats | None = None,
                          chunk_epochs: int = CHUNK_EPOCHS) -> Iterator[NmeaTables]:  # fmt: skip
    """The epoch and satellite tables of a gpsd JSON stream, chunk by chunk (see the module's description)."""
    stats = stats if stats is not None else ReadStats()
    builder = TableBuilder(stats)
    state = _Epochs(builder, stats)
    for block in text_line_blocks(source, stats):
        for line_no, text in block:
            if not text.startswith("{"):
                if text.startswith("#"):
                    stats.comments += 1
                else:
                    stats.unused += 1
                continue
            try:
                report = _DECODER.decode(text)
                kind = report["class"]
            except _TooLarge:  # a field no receiver writes: the report is malformed, skipped and counted
                skip_malformed(stats, line_no, TOO_LARGE, strict)
                continue
            except (ValueError, KeyError, TypeError, RecursionError) as exc:
                skip_malformed(stats, line_no, f"not a gpsd JSON report ({type(exc).__name__})", strict)
                continue
            damage = _damaged(report)
            if damage:  # a field no receiver writes: the report is malformed, skipped and counted (--strict: an error)
                skip_malformed(stats, line_no, damage, strict)
                continue
            stats.sentences += 1
            state.add(kind, report, line_no)
        if len(builder) >= chunk_epochs:
            tables = builder.take()
            if tables is not None:
                yield tables
    state.close()
    tables = builder.take()
    if tables is not None:
        yield tables


class _Epochs:
    """TPVs merged by time, with the SKY and GST reports that belong to them.

    The epochs of the last ``REREPORT_S`` seconds stay open: a TPV of one of their times (gpsd re-reporting a fix
    from another of the receiver's messages, as with SiRF) joins it; older epochs are closed, in time order."""

    def __init__(self, builder: TableBuilder, stats: ReadStats) -> None:
        self.builder, self.stats = builder, stats
        self.open: dict = {}  # time ms (or a line number for TPVs without time) → epoch: time, line, fields, sats
        self.pending: list[tuple] = []  # SKY/GST waiting for their TPV: (class, time, report), in order
        self.last_sky: tuple[int | None, list, dict] | None = None  # (time ms, satellites, fields)

    def add(self, kind: str, report: dict, line: int) -> None:
        if kind not in ("TPV", "SKY", "GST"):
            self.stats.unused += 1
            return
        when = _time_ms(report.get("time"))
        if kind == "TPV" and when is None:
            self.stats.untimed_reports += 1  # a fix without a time belongs to no epoch (no fix yet, or a receiver's quirk)
            return
        if kind == "TPV":
            key = when if when is not None else ("line", line)
            timed = [k for k in self.open if isinstance(k, int)]
            near = [k for k in timed if when is not None and abs(k - when) <= SAME_FIX_MS]
            if key in self.open or near:
                self.open[key if key in self.open else near[0]]["fields"].update(_tpv_fields(report))
                return
            if when is not None and timed and max(timed) - REREPORT_S * 1000 <= when < min(timed):
                self.stats.unused += 1  # a re-report of a second already closed
                return
            if when is None or (timed and when < max(timed) - REREPORT_S * 1000):
                self.close()  # no clock, or a clock that jumped back: the open epochs are done
            self.close(before=None if when is None else when - REREPORT_S * 1000)
            epoch = {"time": when, "line": line, "fields": _tpv_fields(report), "sats": None}
            self.open[key] = epoch
            for k, t, r in self.pending:  # the reports of this cycle, sent before its TPV
                if t is None or when is None or 0 <= when - t <= SKY_MAX_AGE_S * 1000:
                    self._attach(epoch, k, r, t)
            self.pending.clear()
            return
        if when is not None and when in self.open:
            self._attach(self.open[when], kind, report, when)
        else:
            if len(self.pending) > 64:  # reports no TPV claims (a receiver without a fix): keep the latest
                del self.pending[:32]
            self.pending.append((kind, when, report))

    def _attach(self, epoch: dict, kind: str, report: dict, when: int | None) -> None:
        if kind == "SKY":
            sats = _sky_satellites(report)
            fields = _sky_fields(report)
            if sats:
                epoch["sats"] = sats
                self.last_sky = (when, sats, fields)
            epoch["fields"].update(fields)
        else:
            epoch["fields"].update(_gst_fields(report))

    def close(self, before: int | None = None) -> None:
        """Close the open epochs (``before``: only those older than this time), in time order."""
        keys = [k for k in self.open if before is None or (isinstance(k, int) and k < before)]
        for key in sorted(keys, key=lambda k: (0, k) if isinstance(k, int) else (1, k[1])):
            self._emit(self.open.pop(key))

    def _emit(self, current: dict) -> None:
        if "lat_deg" not in current["fields"]:
            return
        sats = current["sats"]
        if sats is None and self.last_sky is not None and current["time"] is not None and self.last_sky[0] is not None:
            if 0 <= current["time"] - self.last_sky[0] <= SKY_MAX_AGE_S * 1000:
                sats = self.last_sky[1]
                for k, v in self.last_sky[2].items():
                    current["fields"].setdefault(k, v)
        fields = current["fields"]
        if sats is not None:
            fields["n_in_view"] = len(sats)
            fields.setdefault("n_used", sum(1 for s in sats if s[5]))
        index = self.builder.add_epoch(current["time"], current["line"], **fields)
        for name, svid, el, az, ss, used, residual, prn in sats or ():
            self.builder.add_satellite(index, name, svid, el, az, ss, used, residual, prn)
        self.stats.decoded += 1
