"""One log charged under a city tariff: gantry crossings and zone presences proven by valid positions, then the
tariff's rules (``charging/city_rules.py``) — the invoice ``process`` writes when the tariff says ``scheme = "city"``.

The log is read as for sections (``pipeline.py``'s chunk sources: NMEA and the other navigation logs streamed, a
pseudorange log placed by the trajectory estimator when ``--positioning`` gives one); each chunk's RAIM runs once per
HAL the city's objects use, on the epochs near an object of that HAL only.
"""

from __future__ import annotations

import datetime as dt
import os
from dataclasses import asdict, replace
from decimal import Decimal

import numpy as np
import pandas as pd

from tollcli.charging.city_evidence import (
    CROSSING_GAP_S,
    PRESENCE_GAP_S,
    object_rows,
    path_crossings,
    presences,
    proven_crossings,
    unproven_crossings,
)
from tollcli.charging.city_rules import Charge, apply_rules
from tollcli.charging.city_tariff import CityTariff, load_city_tariff
from tollcli.charging.invoice import seal
from tollcli.charging.recognition import utc_seconds
from tollcli.errors import UsageError
from tollcli.geodesy import enu_shift2geodetic
from tollcli.geoobjects.city import CityNetwork, load_city_network
from tollcli.gnss.sigma_models import NominalModel
from tollcli.integrity.environment import EnvironmentCarry
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import level_name, run_raim, settle_sources
from tollcli.integrity.sources import LEVELS
from tollcli.io.log_run import LogRun
from tollcli.io.sources import file_sha256, printable_path
from tollcli.job.log_integrity import measured_environment
from tollcli.readers.navigation import NAVIGATION_KINDS
from tollcli.readers.nmea import ReadStats
from tollcli.readers.nmea.reader import check_usable

#: how far a position may be from an object's evidence area and still have its RAIM run (its vouched position may
#: lie inside when the raw one does not), m
NEAR_M = 100.0


class _Correlation:
    """Stands in for the section charger: receives the trajectory's correlation time."""

    tc_s: float | None = None

    def independent_after(self, tc_s: float) -> None:
        self.tc_s = tc_s


def check_city_settings(settings, tariff: CityTariff) -> None:
    """UsageError for a vehicle the tariff does not price."""
    if settings.vehicle_class not in tariff.vehicle_classes:
        raise UsageError(f"vehicle_class (--vehicle-class) = {settings.vehicle_class!r}: not a vehicle class of the tariff "
                         f"{tariff.source} ({', '.join(tariff.vehicle_classes)})")  # fmt: skip


def charge_city_log(log: str, geo: str, tariff_path: str, settings, nav=None, epoch_table: list | None = None,
                    as_recorded: dict | None = None, *, reading: dict) -> tuple[dict, ReadStats | None]:  # fmt: skip
    """The city invoice for one log (sealed) and the reader's statistics.

    ``reading``: the section job's own steps (``pipeline.py`` passes them, so that a log is read one way whatever it
    is charged for): ``check_settings``, and the chunk sources ``navigation`` and ``pseudorange``."""
    check_settings, _navigation_chunks, _pseudorange_chunks = reading["check_settings"], reading["navigation"], reading["pseudorange"]
    tariff = load_city_tariff(tariff_path)
    check_settings(settings)
    check_city_settings(settings, tariff)
    net = load_city_network(geo)
    tariff.check_against(net.ids, net.kinds, geo)
    try:
        params = RaimParams(mode=settings.raim, p_md=settings.p_md, p_fa=settings.p_fa, fde=settings.fde, p_sat=settings.p_sat,
                            p_const=settings.p_const, sources=LEVELS.get(settings.integrity_sources))  # fmt: skip
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    from tollcli.spatial import wgs84_to

    to_metric = wgs84_to(net.crs)
    near_areas = [a.buffer(NEAR_M) for a in net.areas]
    rows, paths, kept = [], [], []
    carry = None  # the last raw position of the chunk before: a path crossing can fall between two chunks
    nominal = NominalModel()
    correlation = _Correlation()
    placed: dict[str, str] = {}
    period = [None, None]
    with LogRun(log, settings.input_format) as run:
        kind = run.kind
        stats = ReadStats()  # what the reader passed over (a pseudorange log: its malformed lines)
        with run.named_errors():
            chunks = (_navigation_chunks(run, kind, settings, nominal, stats) if kind in NAVIGATION_KINDS
                      else _pseudorange_chunks(run, kind, nav, settings, nominal, placed, correlation, stats))  # fmt: skip
            env_carry = EnvironmentCarry()
            for epochs, meas, _sats in chunks:
                params = settle_sources(params, meas)
                meas, _env = measured_environment(epochs, meas, settings.environment, env_carry)
                t = utc_seconds(epochs["time_utc"])
                lat, lon = epochs["lat_deg"].to_numpy(float), epochs["lon_deg"].to_numpy(float)
                x, y = (np.asarray(v, float) for v in to_metric.transform(lon, lat))
                have = np.isfinite(t)
                if have.any():
                    period[0] = period[0] if period[0] is not None else float(np.nanmin(t))
                    period[1] = float(np.nanmax(t))
                px, py, pt = (np.r_[carry[i], v] if carry is not None else v for i, v in enumerate((x, y, t)))
                paths.append(path_crossings(net, pt, px, py))
                fixed = np.flatnonzero(np.isfinite(x) & np.isfinite(y) & have)
                if len(fixed):
                    carry = (x[fixed[-1]], y[fixed[-1]], t[fixed[-1]])
                rows.extend(_chunk_rows(net, near_areas, params, meas, t, x, y, lat, lon, to_metric))
                if epoch_table is not None:
                    kept.append(epochs[[c for c in ("epoch", "time_utc", "line", "lat_deg", "lon_deg", "fix_valid") if c in epochs]])
            if kind in NAVIGATION_KINDS:
                check_usable(stats)
        stats.source, stats.first_problem = run.named(stats.source), run.named(stats.first_problem)  # (not the log's copy)
        log_sha256 = run.sha256
        decoded_by = run.decoded_by
    if epoch_table is not None:
        epoch_table.append(pd.concat(kept, ignore_index=True) if kept else pd.DataFrame({"time_utc": []}))
    table = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(columns=["obj", "t_s", "status", "valid", "evidence", "distance_m"])
    path_table = pd.concat(paths, ignore_index=True) if paths else pd.DataFrame(columns=["obj", "t_s", "direction", "gap_s"])
    tc_s = max(settings.tc_s, correlation.tc_s or 0.0)
    inputs = {"log": printable_path(log), "geoobjects": printable_path(geo), "tariff": printable_path(tariff_path),
              "geoobjects_sha256": net.source_sha256, "tariff_sha256": file_sha256(tariff_path)}  # fmt: skip
    if log != "-":
        inputs["log_sha256"] = log_sha256
    if decoded_by:  # a binary protocol read through gpsd's decoder: another version may read other positions
        inputs["log_decoded_by"] = decoded_by
    if isinstance(nav, str):
        inputs.update(nav=printable_path(nav), nav_sha256=file_sha256(nav))
    elif nav is not None:
        inputs.update(nav=[printable_path(p) for p in nav], nav_sha256=[file_sha256(p) for p in nav])
    inputs.update({k: v for k, v in (as_recorded or {}).items() if k in inputs})
    parameters = {k: v for k, v in asdict(settings).items() if k != "continued"}  # (batch compares them to skip a log done)
    parameters.update(integrity_sources_used=level_name(params.sources) or "residual", crossing_gap_s=CROSSING_GAP_S,
                      presence_gap_s=PRESENCE_GAP_S)  # fmt: skip
    if kind not in NAVIGATION_KINDS:
        parameters["positioning_used"] = placed.get("positioning", "snapshot")
        if placed.get("note"):
            parameters["positioning_note"] = placed["note"]
    if tc_s != settings.tc_s:
        parameters["tc_used_s"] = tc_s
    invoice = city_invoice(net, tariff, table, path_table, settings, tc_s, log_name=os.path.basename(log))
    from tollcli import __version__

    if settings.vehicle_attrs:
        invoice["vehicle_attributes"] = dict(sorted(settings.vehicle_attrs.items()))
    invoice.update(tool=f"tollcli {__version__}", inputs=inputs, parameters=parameters,
                   vehicle=settings.vehicle or printable_path(os.path.basename(log)), vehicle_class=settings.vehicle_class,
                   period={"start_utc": _iso(period[0]), "end_utc": _iso(period[1])} if period[0] is not None else None)  # fmt: skip
    return seal(invoice), stats


def _chunk_rows(net: CityNetwork, near_areas, params: RaimParams, meas, t, x, y, lat, lon, to_metric) -> list[pd.DataFrame]:
    """The evidence rows of one chunk: the RAIM once per HAL, on the epochs near an object of that HAL."""
    import shapely

    out = []
    for hal in sorted(set(net.hal_m.tolist())):
        objs = np.flatnonzero(net.hal_m == hal)
        near = np.zeros(len(t), bool)
        for k in objs:
            near |= shapely.contains_xy(near_areas[k], x, y)
        sel = np.flatnonzero(near & np.isfinite(t))
        if not len(sel):
            continue
        raim = run_raim(meas.take(sel), replace(params, hal_m=float(hal)))
        east = (raim["fde_shift_e_m"].to_numpy(float) + raim["wls_shift_e_m"].to_numpy(float))
        north = (raim["fde_shift_n_m"].to_numpy(float) + raim["wls_shift_n_m"].to_numpy(float))
        vlat, vlon = enu_shift2geodetic(lat[sel], lon[sel], np.nan_to_num(east), np.nan_to_num(north))
        vx, vy = (np.asarray(v, float) for v in to_metric.transform(vlon, vlat))
        hpl = raim["hpl_m"].to_numpy(float)
        hpl = np.where(np.isfinite(hpl), hpl, np.inf)
        status = raim["raim_status"].astype(str).to_numpy()
        for k in objs:
            part = object_rows(net, int(k), t[sel], x[sel], y[sel], vx, vy, vlat, vlon, hpl, status)
            if len(part):
                out.append(part)
    return out


def _iso(t_s: float | None) -> str | None:
    if t_s is None or not np.isfinite(t_s):
        return None
    return dt.datetime.fromtimestamp(round(t_s, 3), dt.UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _position(row) -> dict:
    return {"time_utc": _iso(row.t_s), "lat_deg": round(float(row.lat_deg), 7), "lon_deg": round(float(row.lon_deg), 7),
            "distance_m": round(float(row.distance_m), 2), "hpl_m": round(float(row.hpl_m), 2), "status": str(row.status)}  # fmt: skip


def city_invoice(net: CityNetwork, tariff: CityTariff, rows: pd.DataFrame, paths: pd.DataFrame, settings, tc_s: float,
                 log_name: str = "") -> dict:  # fmt: skip
    """The invoice body from a log's evidence rows and raw path crossings: lines (crossings, zone presences), what was
    seen but not charged and why, the rules applied and the days' totals."""
    zone = tariff.zone
    attrs = settings.vehicle_attrs or {}
    crossings = proven_crossings(net, rows, n_th=settings.n_th, tc_s=tc_s) if len(rows) and tariff.rates else []
    unproven = unproven_crossings(net, paths, crossings, rows) if len(paths) and tariff.rates else []
    stays, unstayed = presences(net, rows, tc_s, settings.n_th) if len(rows) and tariff.zone_charges else ([], [])
    lines, not_charged, charges = [], [], []
    for c in crossings:
        gid = net.ids[c["obj"]]
        when = dt.datetime.fromtimestamp(c["t_s"], dt.UTC)
        base = {"kind": "crossing", "geoobject": gid, "name": net.names[c["obj"]], "direction": c["direction"],
                "time_utc": _iso(c["t_s"]), "time_local": when.astimezone(zone).isoformat(timespec="seconds"),
                "interval_utc": [_iso(c["from_s"]), _iso(c["to_s"])],
                "evidence": {"before": [_position(r) for r in c["before"].itertuples()], "after": [_position(r) for r in c["after"].itertuples()]}}  # fmt: skip
        base["statuses"] = _statuses(pd.concat([c["before"], c["after"]]))
        if net.direction[c["obj"]] not in ("both", c["direction"]):
            not_charged.append({**base, "why": f"the direction {c['direction']} is not charged at this gantry (it charges {net.direction[c['obj']]})"})
            continue
        priced = tariff.crossing_price((c["t_s"], c["from_s"], c["to_s"]), gid, c["direction"], settings.vehicle_class, attrs)
        if priced is None:
            free = tariff.calendar.free_reason(when.astimezone(zone).date())
            not_charged.append({**base, "why": "no rate of the tariff holds at this time, gantry and direction" + (f" ({free})" if free else "")})
            continue
        rate, amount = priced
        if amount is None:
            not_charged.append({**base, "rate": rate.name, "why": f"vehicle class {settings.vehicle_class} is exempt from rate {rate.name}"})
            continue
        key = f"{log_name}#{len(lines)}"
        lines.append({**base, "rate": rate.name, "fee": str(amount), "key": key})
        charges.append(Charge("crossing", gid, when, amount, rate.name, c["direction"], True, key))
    for s in stays:
        gid = net.ids[s["obj"]]
        base = {"kind": "zone", "geoobject": gid, "name": net.names[s["obj"]], "entry_utc": _iso(s["from_s"]), "exit_utc": _iso(s["to_s"]),
                "evidence": [_position(r) for r in s["evidence"].itertuples()], "statuses": _statuses(s["evidence"])}  # fmt: skip
        found = False
        for charge in tariff.zone_charges:
            if not charge.applies_to(attrs):
                continue
            at = next((r.t_s for r in s["evidence"].itertuples()
                       if charge.holds(dt.datetime.fromtimestamp(r.t_s, dt.UTC).astimezone(zone), gid)), None)  # fmt: skip
            if at is None:
                continue
            amount = charge.price(settings.vehicle_class)
            if amount is None:
                continue
            found = True
            when = dt.datetime.fromtimestamp(at, dt.UTC)
            key = f"{log_name}#{len(lines)}"
            lines.append({**base, "time_utc": _iso(at), "time_local": when.astimezone(zone).isoformat(timespec="seconds"),
                          "rate": charge.name, "fee": str(amount), "key": key})  # fmt: skip
            charges.append(Charge("zone", gid, when, amount, charge.name, "", charge.calendar, key))
        if not found:
            not_charged.append({**base, "time_utc": _iso(s["from_s"]),
                                "why": "present only outside the zone's charging hours, or no zone charge applies to the vehicle"})  # fmt: skip
    for u in unproven:
        not_charged.append({"kind": "crossing", "geoobject": net.ids[u["obj"]], "name": net.names[u["obj"]], "direction": u["direction"],
                            "time_utc": _iso(u["t_s"]), "why": u["why"], "statuses": u["statuses"], "path_crossings": u["path_crossings"]})  # fmt: skip
    for u in unstayed:
        not_charged.append({"kind": "zone", "geoobject": net.ids[u["obj"]], "name": net.names[u["obj"]], "entry_utc": _iso(u["t_s"]),
                            "exit_utc": _iso(u["to_s"]), "time_utc": _iso(u["t_s"]), "why": u["why"], "statuses": u["statuses"]})  # fmt: skip
    paid, rules, days, total = apply_rules(charges, tariff)
    for line in lines:
        line["charged"] = str(paid[line.pop("key")])
    quantum = Decimal(1).scaleb(-tariff.minor_unit)
    return {"scheme": "city", "currency": tariff.currency, "tariff_rules": tariff.describe(),
            "lines": sorted(lines, key=lambda l: (l["time_utc"], l["geoobject"])),
            "not_charged": sorted(not_charged, key=lambda l: (l["time_utc"] or "", l["geoobject"])),
            "rules": rules, "days": days, "total": str(total.quantize(quantum))}  # fmt: skip


def _statuses(frame: pd.DataFrame) -> dict[str, int]:
    return {str(s): int(n) for s, n in frame["status"].value_counts().sort_index().items()} if len(frame) else {}
