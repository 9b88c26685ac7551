"""Group NMEA sentences into epochs (one per fix time) and satellite rows.

An epoch starts when a time-bearing sentence (GGA, RMC, GLL, GNS, GST, GRS, GBS,
ZDA) carries a time of day different from the current epoch's. Sentences without
a time (GSA, GSV, VTG) belong to the current epoch; those before the first time
wait for it. Within an epoch each quantity has one preferred source:

* position: GGA, then GNS, then RMC, then GLL;
* speed/course: RMC, then VTG;
* DOPs: GSA, HDOP falling back to GGA/GNS;
* ``n_used``: distinct satellites in the epoch's GSA sentences, else GGA/GNS count.

GRS residuals are in the order of the satellites of the GSA they refer to: the
GRS with NMEA 4.10 system id *s* goes with the GSA of system *s*; otherwise the
*n*-th GRS of the epoch goes with the *n*-th GSA.

The assembler only appends finished epochs to column buffers (plain lists, one
per column); :meth:`take` hands them over as numpy arrays and empties them, so
memory is bounded by the chunk size, not the log length.

Why this file is long: it is the reference decoder, one method per sentence type
over one shared epoch state; split, the rules of which source wins for each
quantity (above) would be scattered over files that must change together.
"""

from __future__ import annotations

import math

import numpy as np

from tollcli.readers.nmea.fields import (
    KMH_MPS,
    KNOT_MPS,
    NAN,
    civil_days,
    integer,
    lat_deg,
    lon_deg,
    num,
    rmc_date_days,
    time_of_day_s,
)
from tollcli.readers.nmea.satellite_ids import (
    CONSTELLATIONS,
    SYSTEM_ID_CONSTELLATION,
    TALKER_CONSTELLATION,
    satellite_id,
)

#: epoch float columns, filled from sentences (NaN when no sentence gave them)
FLOAT_COLUMNS = (
    "lat_deg",
    "lon_deg",
    "alt_m",
    "geoid_sep_m",
    "hdop",
    "pdop",
    "vdop",
    "speed_mps",
    "course_deg",
    "rms_residual_m",
    "sigma_major_m",
    "sigma_minor_m",
    "ellipse_orient_deg",
    "sigma_lat_m",
    "sigma_lon_m",
    "sigma_alt_m",
    "gbs_err_lat_m",
    "gbs_err_lon_m",
    "gbs_err_alt_m",
    "gbs_p_md",
    "gbs_bias_m",
    "gbs_bias_sd_m",
    "pos_disagreement_m",
    "date_disagreement_days",
)

#: preference rank of position sources (lower wins)
_POS_RANK = {"GGA": 0, "GNS": 1, "RMC": 2, "GLL": 3}
_VEL_RANK = {"RMC": 0, "VTG": 1}
_CONST_INDEX = {name: i for i, name in enumerate(CONSTELLATIONS)}
_GGA_VALID_QUALITY = {1, 2, 3, 4, 5}  # 0 invalid, 6 dead reckoning, 7 manual, 8 simulator


class _Epoch:
    """The epoch being assembled (transient; one at a time)."""

    __slots__ = (
        "tod_s",
        "date_days",
        "line",
        "values",
        "pos_rank",
        "vel_rank",
        "course_rank",
        "fix_quality",
        "fix_mode",
        "status",
        "mode_indicator",
        "n_used_gga",
        "view",
        "gsv_seen",
        "used",
        "grs",
        "gbs_svid",
    )

    def __init__(self, line: int):
        self.tod_s = NAN
        self.date_days = -1
        self.line = line
        self.values: dict[str, float] = {}
        self.pos_rank = 99
        self.vel_rank = 99
        self.course_rank = 99
        self.fix_quality = -1
        self.fix_mode = -1
        self.status = ""  # 'A' or 'V' from RMC/GLL
        self.mode_indicator = ""
        self.n_used_gga = -1
        # (constellation, svid) -> (signal_id, prn, elev, azim, cn0)
        self.view: dict[tuple[str, int], tuple[int, int, float, float, float]] = {}
        self.gsv_seen = False  # a GSV sentence (even one listing no satellite) was in the epoch
        self.used: list[tuple[int | None, list[tuple[str, int]]]] = []
        self.grs: list[tuple[int | None, list[float]]] = []
        self.gbs_svid = -1


class EpochAssembler:
    """Feed it sentences with :meth:`feed`; collect finished epochs with :meth:`take`."""

    def __init__(self) -> None:
        self._cur: _Epoch | None = None
        self._next_epoch = 0
        self._reset_buffers()
        self._handlers = {
            "GGA": self._gga,
            "RMC": self._rmc,
            "GLL": self._gll,
            "GNS": self._gns,
            "VTG": self._vtg,
            "GSA": self._gsa,
            "GSV": self._gsv,
            "GST": self._gst,
            "GRS": self._grs,
            "GBS": self._gbs,
            "ZDA": self._zda,
        }

    # ------------------------------------------------------------------ buffers
    def _reset_buffers(self) -> None:
        self.e_epoch: list[int] = []
        self.e_tod: list[float] = []
        self.e_date: list[int] = []
        self.e_line: list[int] = []
        self.e_float: dict[str, list[float]] = {k: [] for k in FLOAT_COLUMNS}
        self.e_fix_quality: list[int] = []
        self.e_fix_mode: list[int] = []
        self.e_fix_valid: list[bool] = []
        self.e_mode: list[str] = []
        self.e_n_used: list[int] = []
        self.e_n_view: list[int] = []
        self.e_gbs_svid: list[int] = []
        self.s_epoch: list[int] = []
        self.s_const: list[int] = []  # index into satellite_ids.CONSTELLATIONS
        self.s_svid: list[int] = []
        self.s_prn: list[int] = []
        self.s_signal: list[int] = []
        self.s_elev: list[float] = []
        self.s_azim: list[float] = []
        self.s_cn0: list[float] = []
        self.s_used: list[bool] = []
        self.s_resid: list[float] = []

    def handles(self, sentence_type: str) -> bool:
        return sentence_type in self._handlers

    def handled_types(self) -> tuple[str, ...]:
        return tuple(self._handlers)

    @property
    def n_ready(self) -> int:
        """Finished epochs waiting in the buffers."""
        return len(self.e_epoch)

    def feed(self, talker: str, sentence_type: str, fields: list[str], line: int) -> None:
        """Decode one checksum-verified sentence. Raises ValueError when malformed."""
        self._handlers[sentence_type](talker, fields, line)

    def finish(self) -> None:
        """End of input: close the open epoch."""
        self._close()

    def take(self) -> dict[str, np.ndarray]:
        """Hand over the finished epochs as arrays and empty the buffers."""
        n_sat = len(self.s_epoch)
        out = {
            "epoch": np.asarray(self.e_epoch, dtype=np.int64),
            "tod_s": np.asarray(self.e_tod, dtype=np.float64),
            "date_days": np.asarray(self.e_date, dtype=np.int64),
            "line": np.asarray(self.e_line, dtype=np.int64),
            "fix_quality": np.asarray(self.e_fix_quality, dtype=np.int8),
            "fix_mode": np.asarray(self.e_fix_mode, dtype=np.int8),
            "fix_valid": np.asarray(self.e_fix_valid, dtype=bool),
            "mode_indicator": np.asarray(self.e_mode, dtype=object),
            "n_used": np.asarray(self.e_n_used, dtype=np.int16),
            "n_in_view": np.asarray(self.e_n_view, dtype=np.int16),
            "gbs_failed_svid": np.asarray(self.e_gbs_svid, dtype=np.int16),
            "sat_epoch": np.asarray(self.s_epoch, dtype=np.int64).reshape(n_sat),
            "sat_constellation": np.asarray(self.s_const, dtype=np.int8).reshape(n_sat),
            "sat_svid": np.asarray(self.s_svid, dtype=np.int16).reshape(n_sat),
            "sat_prn": np.asarray(self.s_prn, dtype=np.int16).reshape(n_sat),
            "sat_signal_id": np.asarray(self.s_signal, dtype=np.int8).reshape(n_sat),
            "sat_elev_deg": np.asarray(self.s_elev, dtype=np.float64).reshape(n_sat),
            "sat_azim_deg": np.asarray(self.s_azim, dtype=np.float64).reshape(n_sat),
            "sat_cn0_dbhz": np.asarray(self.s_cn0, dtype=np.float64).reshape(n_sat),
            "sat_used": np.asarray(self.s_used, dtype=bool).reshape(n_sat),
            "sat_residual_m": np.asarray(self.s_resid, dtype=np.float64).reshape(n_sat),
        }
        for key, values in self.e_float.items():
            out[key] = np.asarray(values, dtype=np.float64)
        self._reset_buffers()
        return out

    # ------------------------------------------------------------------ epochs
    def _epoch_for(self, line: int) -> _Epoch:
        """The current epoch, opened if there is none (untimed sentences)."""
        if self._cur is None:
            self._cur = _Epoch(line)
        return self._cur

    def _at(self, tod_s: float, line: int) -> _Epoch:
        """The epoch for time of day ``tod_s``; a new time closes the current one."""
        cur = self._cur
        if math.isnan(tod_s):
            return self._epoch_for(line)
        if cur is not None:
            if math.isnan(cur.tod_s):
                cur.tod_s = tod_s
                return cur
            if abs(cur.tod_s - tod_s) < 5e-4:
                return cur
            self._close()
        cur = self._cur = _Epoch(line)
        cur.tod_s = tod_s
        return cur

    def _close(self) -> None:
        cur = self._cur
        self._cur = None
        if cur is None or math.isnan(cur.tod_s):
            return  # no time: nothing can be said about when it was
        epoch = self._next_epoch
        self._next_epoch += 1
        self.e_epoch.append(epoch)
        self.e_tod.append(cur.tod_s)
        self.e_date.append(cur.date_days)
        self.e_line.append(cur.line)
        values = cur.values
        for key, column in self.e_float.items():
            column.append(values.get(key, NAN))
        self.e_fix_quality.append(cur.fix_quality)
        self.e_fix_mode.append(cur.fix_mode)
        self.e_fix_valid.append(_fix_valid(cur))
        self.e_mode.append(cur.mode_indicator)
        self.e_gbs_svid.append(cur.gbs_svid)
        self._close_satellites(cur, epoch)

    def _close_satellites(self, cur: _Epoch, epoch: int) -> None:
        residual: dict[tuple[str, int], float] = {}
        used_keys: list[tuple[str, int]] = []
        for seq, (sysid, keys) in enumerate(cur.used):
            used_keys.extend(keys)
            grs = _matching_grs(cur.grs, seq, sysid, keys)
            if grs is not None:
                for key, r in zip(keys, grs):
                    residual[key] = r
        used = set(used_keys)
        n_used = len(used) if cur.used else cur.n_used_gga
        self.e_n_used.append(n_used)
        self.e_n_view.append(len(cur.view) if cur.gsv_seen else -1)
        keys = sorted(set(cur.view) | used, key=lambda k: (_CONST_INDEX[k[0]], k[1]))
        for key in keys:
            signal, prn, elev, azim, cn0 = cur.view.get(key, (-1, -1, NAN, NAN, NAN))
            self.s_epoch.append(epoch)
            self.s_const.append(_CONST_INDEX[key[0]])
            self.s_svid.append(key[1])
            self.s_prn.append(prn)
            self.s_signal.append(signal)
            self.s_elev.append(elev)
            self.s_azim.append(azim)
            self.s_cn0.append(cn0)
            self.s_used.append(key in used)
            self.s_resid.append(residual.get(key, NAN))

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _position(ep: _Epoch, source: str, lat: float, lon: float) -> None:
        if math.isnan(lat) or math.isnan(lon):
            return
        rank = _POS_RANK[source]
        if ep.pos_rank < 99 and rank != ep.pos_rank:  # two sentences place this epoch: how far apart?
            dn = (lat - ep.values["lat_deg"]) * 111_195.0
            de = (lon - ep.values["lon_deg"]) * 111_195.0 * math.cos(math.radians(lat))
            gap = math.hypot(dn, de)
            if gap > ep.values.get("pos_disagreement_m", -1.0):
                ep.values["pos_disagreement_m"] = gap
        if rank < ep.pos_rank:
            ep.pos_rank = rank
            ep.values["lat_deg"] = lat
            ep.values["lon_deg"] = lon

    @staticmethod
    def _date(ep: _Epoch, date: int) -> None:
        """Set the epoch's date; a second, different date (RMC vs ZDA) is recorded as a disagreement."""
        if date < 0:
            return
        if ep.date_days >= 0 and date != ep.date_days:
            ep.values["date_disagreement_days"] = float(date - ep.date_days)
        ep.date_days = date

    @staticmethod
    def _velocity(ep: _Epoch, source: str, speed_mps: float, course_deg: float) -> None:
        rank = _VEL_RANK[source]
        if not math.isnan(speed_mps) and rank < ep.vel_rank:
            ep.vel_rank = rank
            ep.values["speed_mps"] = speed_mps
        if not math.isnan(course_deg) and rank < ep.course_rank:
            ep.course_rank = rank
            ep.values["course_deg"] = course_deg

    @staticmethod
    def _set(ep: _Epoch, **values: float) -> None:
        for key, value in values.items():
            if not math.isnan(value):
                ep.values[key] = value

    @staticmethod
    def _set_default(ep: _Epoch, **values: float) -> None:
        for key, value in values.items():
            if not math.isnan(value):
                ep.values.setdefault(key, value)

    # ------------------------------------------------------------------ sentences
    def _gga(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 9)
        tod = time_of_day_s(f[0])
        quality = integer(f[5], hi=127)
        lat, lon = _latlon(f, 1, quality != 0)
        n_used = integer(f[6], hi=9_999)
        hdop = num(f[7])
        alt = num(f[8])
        sep = num(f[10]) if len(f) > 10 else NAN
        ep = self._at(tod, line)
        if quality >= 0:
            ep.fix_quality = quality
        if n_used >= 0:
            ep.n_used_gga = n_used
        if quality != 0:
            self._position(ep, "GGA", lat, lon)
            self._set(ep, alt_m=alt, geoid_sep_m=sep)
        self._set_default(ep, hdop=hdop)

    def _gns(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 9)
        tod = time_of_day_s(f[0])
        mode = f[5]
        has_fix = any(c in "ADPRFM" for c in mode)
        lat, lon = _latlon(f, 1, has_fix)
        n_used = integer(f[6], hi=9_999)
        hdop = num(f[7])
        alt = num(f[8])
        sep = num(f[9]) if len(f) > 9 else NAN
        ep = self._at(tod, line)
        if mode and not ep.mode_indicator:
            ep.mode_indicator = mode[0]
        if n_used >= 0 and ep.n_used_gga < 0:
            ep.n_used_gga = n_used
        if has_fix:
            self._position(ep, "GNS", lat, lon)
            if "alt_m" not in ep.values:
                self._set(ep, alt_m=alt, geoid_sep_m=sep)
        self._set_default(ep, hdop=hdop)

    def _rmc(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 9)
        tod = time_of_day_s(f[0])
        status = f[1]
        lat, lon = _latlon(f, 2, status == "A")
        speed = num(f[6]) * KNOT_MPS
        course = num(f[7])
        date = rmc_date_days(f[8]) if status == "A" else -1  # without a fix the date is the chip's guess
        mode = f[11] if len(f) > 11 else ""
        ep = self._at(tod, line)
        self._date(ep, date)
        if status in ("A", "V"):
            ep.status = ep.status or status
        if mode:
            ep.mode_indicator = ep.mode_indicator or mode[:1]
        if status == "A":
            self._position(ep, "RMC", lat, lon)
            self._velocity(ep, "RMC", speed, course)

    def _gll(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 4)
        tod = time_of_day_s(f[4]) if len(f) > 4 else NAN
        status = f[5] if len(f) > 5 else ""
        lat, lon = _latlon(f, 0, status != "V")
        mode = f[6] if len(f) > 6 else ""
        ep = self._at(tod, line)
        if status in ("A", "V"):
            ep.status = ep.status or status
        if mode:
            ep.mode_indicator = ep.mode_indicator or mode[:1]
        if status != "V":
            self._position(ep, "GLL", lat, lon)

    def _vtg(self, talker: str, f: list[str], line: int) -> None:
        if len(f) >= 7 and f[1] in ("T", ""):
            course = num(f[0])
            knots = num(f[4])
            kmh = num(f[6])
            mode = f[8] if len(f) > 8 else ""
        else:  # NMEA 1.5 layout: course true, course magnetic, knots, km/h
            _need(f, 4)
            course = num(f[0])
            knots = num(f[2])
            kmh = num(f[3])
            mode = ""
        if mode == "N":
            return
        speed = kmh * KMH_MPS if not math.isnan(kmh) else knots * KNOT_MPS
        self._velocity(self._epoch_for(line), "VTG", speed, course)

    def _gsa(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 5)
        sysid: int | None = None
        if len(f) >= 18 and len(f[-1]) == 1 and f[-1].isdigit():
            sysid = int(f[-1])
            dops, prns = f[-4:-1], f[2:-4]
        else:
            dops, prns = f[-3:], f[2:-3]
        pdop, hdop, vdop = num(dops[0]), num(dops[1]), num(dops[2])
        fix_mode = integer(f[1], hi=127)
        hint = SYSTEM_ID_CONSTELLATION.get(sysid) if sysid else TALKER_CONSTELLATION.get(talker)
        keys = [satellite_id(hint, integer(p, lo=1, hi=9_999)) for p in prns if p]
        ep = self._epoch_for(line)
        if fix_mode > ep.fix_mode:
            ep.fix_mode = fix_mode
        ep.used.append((sysid, keys))
        self._set(ep, pdop=pdop, hdop=hdop, vdop=vdop)

    def _gsv(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 3)
        body = f[3:]
        signal = -1
        if len(body) % 4 == 1:
            signal = int(body[-1], 16) if body[-1] else -1
            if not -1 <= signal <= 127:
                raise ValueError(f"signal id {body[-1]!r}")
            body = body[:-1]
        hint = TALKER_CONSTELLATION.get(talker)
        rows = []
        for i in range(0, len(body) - 3, 4):
            prn_text = body[i]
            if not prn_text:
                continue
            prn = integer(prn_text, lo=1, hi=9_999)
            key = satellite_id(hint, prn)
            elev = num(body[i + 1])
            azim = num(body[i + 2])
            cn0 = num(body[i + 3])
            if not math.isnan(elev) and not -90.0 <= elev <= 90.0:
                raise ValueError(f"elevation {elev}")
            if not math.isnan(azim) and not 0.0 <= azim <= 360.0:
                raise ValueError(f"azimuth {azim}")
            rows.append((key, (signal, prn, elev, azim, cn0)))
        epoch = self._epoch_for(line)
        epoch.gsv_seen = True
        view = epoch.view
        for key, value in rows:
            old = view.get(key)
            # keep the lowest signal id (the primary signal); same signal: the latest report
            if old is None or value[0] <= old[0] or old[0] < 0:
                view[key] = value

    def _gst(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 8)
        tod = time_of_day_s(f[0])
        values = dict(
            rms_residual_m=num(f[1]),
            sigma_major_m=num(f[2]),
            sigma_minor_m=num(f[3]),
            ellipse_orient_deg=num(f[4]),
            sigma_lat_m=num(f[5]),
            sigma_lon_m=num(f[6]),
            sigma_alt_m=num(f[7]),
        )
        self._set(self._at(tod, line), **values)

    def _grs(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 3)
        tod = time_of_day_s(f[0])
        body = f[2:]
        sysid: int | None = None
        if len(body) == 14:  # NMEA 4.10: 12 residuals, system id, signal id
            sysid = integer(body[12]) if body[12] else None
            body = body[:12]
        residuals = [num(r) for r in body]
        while residuals and math.isnan(residuals[-1]):
            residuals.pop()
        self._at(tod, line).grs.append((sysid, residuals))

    def _gbs(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 8)
        tod = time_of_day_s(f[0])
        values = dict(
            gbs_err_lat_m=num(f[1]),
            gbs_err_lon_m=num(f[2]),
            gbs_err_alt_m=num(f[3]),
            gbs_p_md=num(f[5]),
            gbs_bias_m=num(f[6]),
            gbs_bias_sd_m=num(f[7]),
        )
        svid = integer(f[4], hi=9_999)
        ep = self._at(tod, line)
        self._set(ep, **values)
        if svid >= 0:
            ep.gbs_svid = svid

    def _zda(self, talker: str, f: list[str], line: int) -> None:
        _need(f, 4)
        tod = time_of_day_s(f[0])
        date = -1
        if f[1] and f[2] and f[3]:
            date = civil_days(int(f[1]), int(f[2]), int(f[3]))
        ep = self._at(tod, line)
        self._date(ep, date)


def _latlon(f: list[str], k: int, fix: bool) -> tuple[float, float]:
    """Latitude and longitude from fields ``k`` … ``k + 3``, read only when the sentence says it has a fix.

    A sentence that says it has none carries no position: what its position fields hold is a
    placeholder, not an error (MediaTek chips write ``8960.000000``, 89°60′, until their first fix).
    """
    if not fix:
        return NAN, NAN
    return lat_deg(f[k], f[k + 1]), lon_deg(f[k + 2], f[k + 3])


def _need(f: list[str], n: int) -> None:
    if len(f) < n:
        raise ValueError(f"{len(f)} fields, expected at least {n}")


def _matching_grs(
    grs: list[tuple[int | None, list[float]]],
    seq: int,
    sysid: int | None,
    keys: list[tuple[str, int]],
) -> list[float] | None:
    """The GRS residual list that belongs to the ``seq``-th GSA of an epoch."""
    if sysid is not None:
        for g_sys, residuals in grs:
            if g_sys == sysid:
                return residuals if len(residuals) == len(keys) else None
    if seq < len(grs) and grs[seq][0] in (None, sysid):
        residuals = grs[seq][1]
        return residuals if len(residuals) == len(keys) else None
    return None


def _fix_valid(ep: _Epoch) -> bool:
    """Did the receiver claim a GNSS fix for this epoch?"""
    if ep.pos_rank == 99:
        return False
    if ep.fix_quality >= 0:
        return ep.fix_quality in _GGA_VALID_QUALITY
    if ep.status:
        return ep.status == "A" and ep.mode_indicator not in ("E", "N", "M", "S")
    if ep.fix_mode >= 0:
        return ep.fix_mode >= 2
    return ep.mode_indicator not in ("E", "N", "M", "S")
