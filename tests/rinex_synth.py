"""Write small RINEX 3.04 observation and navigation files with a known receiver position.

Test data only. Satellites: Walker-like GPS (6 planes × 4) and Galileo (3 × 8)
broadcast ephemerides; pseudoranges from the light-time solution (with the
Earth's rotation), satellite clocks with relativity and group delay, Klobuchar
ionosphere, Saastamoinen troposphere, receiver clocks per constellation.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from tollcli.geodesy import OMEGA_EARTH_RADPS, geodetic2ecef
from tollcli.gnss.atmosphere import klobuchar_delay_m, saastamoinen_delay_m
from tollcli.gnss.orbits import WEEK_S, kepler_position_clock
from tollcli.gnss.pseudorange_wls import C_MPS, local_angles

GPS_EPOCH = dt.datetime(1980, 1, 6)
ALPHA = (1.1176e-08, 1.4901e-08, -5.9605e-08, -1.1921e-07)
BETA = (9.0112e04, 1.6384e04, -1.9661e05, -6.5536e04)


def constellation(start: dt.datetime) -> list[dict]:
    gps_s = (start - GPS_EPOCH).total_seconds()
    week, tow = divmod(gps_s, WEEK_S)
    rng = np.random.default_rng(11)
    sats = []
    for system, planes, per_plane, a, inc in (("G", 6, 4, 26_559_700.0, 55.0), ("E", 3, 8, 29_600_000.0, 56.0)):
        for p in range(planes):
            for j in range(per_plane):
                prn = p * per_plane + j + 1
                sats.append({
                    "sv": f"{system}{prn:02d}", "toc": start, "week": week,
                    "SVclockBias": rng.uniform(-2e-4, 2e-4), "SVclockDrift": rng.uniform(-1e-11, 1e-11), "SVclockDriftRate": 0.0,
                    "IODE": 1.0, "Crs": 20.0, "DeltaN": 4.5e-9, "M0": np.radians(360.0 * j / per_plane + 15.0 * p) - np.pi,
                    "Cuc": 1e-6, "Eccentricity": 0.004 + 0.001 * (prn % 5), "Cus": 5e-6, "sqrtA": np.sqrt(a),
                    "Toe": tow, "Cic": 1e-8, "Omega0": np.radians(360.0 * p / planes) - np.pi, "Cis": -1e-8,
                    "Io": np.radians(inc), "Crc": 200.0, "omega": np.radians(30.0 + 7 * prn), "OmegaDot": -8e-9,
                    "IDOT": 1e-10, "TGD": -1.1e-8 if system == "G" else 0.0, "BGD": 2.3e-9 if system == "E" else 0.0,
                })  # fmt: skip
    return sats


def _eph_arrays(sats: list[dict], idx: np.ndarray) -> dict[str, np.ndarray]:
    keys = ("SVclockBias", "SVclockDrift", "SVclockDriftRate", "Crs", "DeltaN", "M0", "Cuc", "Eccentricity", "Cus",
            "sqrtA", "Cic", "Omega0", "Cis", "Io", "Crc", "omega", "OmegaDot", "IDOT")  # fmt: skip
    eph = {k: np.array([sats[i][k] for i in idx]) for k in keys}
    eph["toc_s"] = np.array([(sats[i]["toc"] - GPS_EPOCH).total_seconds() for i in idx])
    eph["toe_s"] = np.array([sats[i]["week"] * WEEK_S + sats[i]["Toe"] for i in idx])
    eph["group_delay_s"] = np.array([sats[i]["TGD"] if sats[i]["sv"][0] == "G" else sats[i]["BGD"] for i in idx])
    return eph


def observe(sats, start, n_epochs, lat, lon, h, clock_m=(120.0, 150.0), mask_deg=10.0, noise_m=0.0, seed=0):
    """Rows (epoch k, sv, pr_m, cn0) for satellites above the mask, and the truth."""
    rx = np.array(geodetic2ecef(lat, lon, h))
    rng = np.random.default_rng(seed)
    rows = []
    idx = np.arange(len(sats))
    eph = _eph_arrays(sats, idx)
    galileo = np.array([s["sv"][0] == "E" for s in sats])
    for k in range(n_epochs):
        t_rx = (start - GPS_EPOCH).total_seconds() + k
        tau = np.full(idx.size, 0.075)
        for _ in range(8):  # light time with Earth rotation (receiver frame at t_rx)
            pos, clock = kepler_position_clock(eph, t_rx - tau, galileo)
            theta = OMEGA_EARTH_RADPS * tau
            rot = np.stack([np.cos(theta) * pos[:, 0] + np.sin(theta) * pos[:, 1],
                            -np.sin(theta) * pos[:, 0] + np.cos(theta) * pos[:, 1], pos[:, 2]], -1)  # fmt: skip
            rho = np.linalg.norm(rot - rx, axis=1)
            tau = rho / C_MPS
        los = ((rot - rx) / rho[:, None])[None]
        _, elev, azim = local_angles(los, np.array([lat]), np.array([lon]))
        elev, azim = elev[0], azim[0]
        tow = np.mod(t_rx, WEEK_S)
        atm = saastamoinen_delay_m(lat, h, elev) + klobuchar_delay_m(lat, lon, elev, azim, tow, ALPHA, BETA)
        rx_clock = np.where(galileo, clock_m[1], clock_m[0])
        pr = rho + rx_clock - C_MPS * clock + atm + noise_m * rng.normal(size=idx.size)
        for i in np.flatnonzero(elev > mask_deg):
            rows.append((k, sats[i]["sv"], pr[i], 35.0 + elev[i] / 6.0))
    return rows


def _d(v: float) -> str:
    return f"{v:19.12E}"


def write_nav(path: Path, sats: list[dict]) -> None:
    head = [
        f"{'3.04':>9}{'':11}{'N: GNSS NAV DATA':<20}{'M: MIXED':<20}RINEX VERSION / TYPE",
        f"{'GPSA ' + ''.join(f'{a:12.4E}' for a in ALPHA):<60}IONOSPHERIC CORR",
        f"{'GPSB ' + ''.join(f'{b:12.4E}' for b in BETA):<60}IONOSPHERIC CORR",
        f"{'':60}END OF HEADER",
    ]
    body = []
    for s in sats:
        t = s["toc"]
        body.append(f"{s['sv']} {t:%Y %m %d %H %M %S}" + _d(s["SVclockBias"]) + _d(s["SVclockDrift"]) + _d(s["SVclockDriftRate"]))
        gal = s["sv"][0] == "E"
        lines = [
            (s["IODE"], s["Crs"], s["DeltaN"], s["M0"]),
            (s["Cuc"], s["Eccentricity"], s["Cus"], s["sqrtA"]),
            (s["Toe"], s["Cic"], s["Omega0"], s["Cis"]),
            (s["Io"], s["Crc"], s["omega"], s["OmegaDot"]),
            (s["IDOT"], 517.0 if gal else 0.0, s["week"], 0.0),
            (3.12 if gal else 2.0, 0.0, s["BGD"] if gal else s["TGD"], s["BGD"] if gal else 1.0),
            (s["Toe"] - 30.0, 0.0 if gal else 4.0),
        ]
        body += ["    " + "".join(_d(v) for v in line) for line in lines]
    path.write_text("\n".join(head + body) + "\n")


def _epochs(rows, start: dt.datetime):
    """(time, the rows of that epoch) for each epoch of ``rows`` (epoch seconds first in each row), in time order."""
    for k in sorted({r[0] for r in rows}):
        yield start + dt.timedelta(seconds=k), [r for r in rows if r[0] == k]


def write_obs(path: Path, rows, start: dt.datetime) -> None:
    head = [
        f"{'3.04':>9}{'':11}{'OBSERVATION DATA':<20}{'M':<20}RINEX VERSION / TYPE",
        f"{'G    2 C1C S1C':<60}SYS / # / OBS TYPES",
        f"{'E    2 C1C S1C':<60}SYS / # / OBS TYPES",
        f"{start.year:6d}{start.month:6d}{start.day:6d}{start.hour:6d}{start.minute:6d}{start.second:13.7f}     GPS         TIME OF FIRST OBS",
        f"{'':60}END OF HEADER",
    ]
    body = []
    for t, epoch_rows in _epochs(rows, start):
        body.append(f"> {t:%Y %m %d %H %M}{t.second + t.microsecond / 1e6:11.7f}  0{len(epoch_rows):3d}")
        body += [f"{sv}{pr:14.3f}  {cn0:14.3f}  " for _, sv, pr, cn0 in epoch_rows]
    path.write_text("\n".join(head + body) + "\n")


def write_obs2(path: Path, rows, start: dt.datetime) -> None:
    """The same observations as :func:`write_obs`, in RINEX 2.11 (types C1 and S1; 12 satellites an epoch line)."""
    head = [
        f"{'2.11':>9}{'':11}{'OBSERVATION DATA':<20}{'M (MIXED)':<20}RINEX VERSION / TYPE",
        f"{'     2    C1    S1':<60}# / TYPES OF OBSERV",
        f"{start.year:6d}{start.month:6d}{start.day:6d}{start.hour:6d}{start.minute:6d}{start.second:13.7f}     GPS         TIME OF FIRST OBS",
        f"{'':60}END OF HEADER",
    ]
    body = []
    for t, epoch_rows in _epochs(rows, start):
        svs = "".join(sv for _, sv, _, _ in epoch_rows)
        first, rest = svs[: 12 * 3], svs[12 * 3 :]
        body.append(f" {t:%y} {t.month:2d} {t.day:2d} {t.hour:2d} {t.minute:2d}{t.second + t.microsecond / 1e6:11.7f}  0{len(epoch_rows):3d}{first}")
        while rest:
            body.append(f"{'':32}{rest[:36]}")
            rest = rest[36:]
        body += [f"{pr:14.3f}  {cn0:14.3f}  " for _, _, pr, cn0 in epoch_rows]
    path.write_text("\n".join(head + body) + "\n")


def make_rinex(folder: Path, n_epochs: int = 5, lat=42.6987, lon=2.8956, h=60.0, noise_m=0.0, seed=0, version: int = 3):
    """Write obs + nav into ``folder``; returns (obs path, nav path, rows). ``version`` 2: the observations in RINEX 2.11."""
    start = dt.datetime(2024, 5, 6, 8, 0, 0)
    sats = constellation(start)
    rows = observe(sats, start, n_epochs, lat, lon, h, noise_m=noise_m, seed=seed)
    obs, nav = folder / "drive.24o", folder / "drive.24n"
    (write_obs2 if version == 2 else write_obs)(obs, rows, start)
    write_nav(nav, sats)
    return obs, nav, rows
