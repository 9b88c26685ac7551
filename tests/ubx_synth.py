"""A u-blox receiver simulated on real broadcast ephemerides: RXM-RAWX + RXM-SFRBX messages built with pyubx2.

Pseudoranges and Doppler are computed from the RINEX navigation file's orbits and clocks for a
receiver at a known position and velocity (with a clock bias and drift); the same ephemerides go
into GPS LNAV subframes 1–3 (``encode_subframes``) and, for Galileo satellites in the table, I/NAV word
types 1–5 (``encode_pages``, E1-B page pairs) as RXM-SFRBX. Nothing here uses the decoder
under test. Noise: ``pr_noise_m`` (the coded prStd 5 = 0.32 m is the receiver's claim, not the truth) and
``dop_noise_hz`` = 0.064 Hz, exactly the coded doStd 5 (0.002·2⁵ Hz), so the Doppler σ the tool derives is true.
"""

from __future__ import annotations

import numpy as np
from pyubx2 import GET, UBXMessage

from tollcli.geodesy import OMEGA_EARTH_RADPS, enu_rotation, geodetic2ecef
from tollcli.gnss.inav_words import encode_pages
from tollcli.gnss.lnav_subframes import encode_subframes
from tollcli.gnss.orbits import WEEK_S
from tollcli.gnss.satellite_states import satellite_states

C = 299_792_458.0
GNSS_ID = {"G": 0, "E": 2}
L1 = 1_575_420_000.0


def _sagnac(xyz, flight):
    th = OMEGA_EARTH_RADPS * flight
    c, s = np.cos(th), np.sin(th)
    return np.stack([c * xyz[:, 0] + s * xyz[:, 1], -s * xyz[:, 0] + c * xyz[:, 1], xyz[:, 2]], -1)


def receiver_epochs(eph_table, t0_gps_s: float, n_epochs: int, lat_deg: float, lon_deg: float, h_m: float,
                    vel_enu_mps=(0.0, 0.0, 0.0), clock_m: float = 30_000.0, drift_mps: float = 120.0,
                    doppler_fault_mps: float = 0.0, seed: int = 0, pr_noise_m: float = 0.5, dop_noise_hz: float = 0.064):  # fmt: skip
    """Per second from ``t0_gps_s``: (t, satellites above 10°, their pseudoranges (m), Dopplers (Hz, L1)) of a
    receiver at the given position moving at ``vel_enu_mps``, its clock ``clock_m`` + ``drift_mps`` per second."""
    rng = np.random.default_rng(seed)
    gps = eph_table[eph_table["sv"].str[0].isin(["G", "E"])]
    svs = np.array(sorted(gps["sv"].unique()))
    R = enu_rotation(np.array([lat_deg]), np.array([lon_deg]))[0]  # rows: e, n, u in ECEF
    v_ecef = R.T @ np.asarray(vel_enu_mps, float)
    x0 = np.array(geodetic2ecef(lat_deg, lon_deg, h_m), float).reshape(3)
    for k in range(n_epochs):
        t = t0_gps_s + k
        rx = x0 + v_ecef * k
        st = satellite_states(eph_table, svs, np.full(svs.size, t), np.full(svs.size, 2.2e7))
        for _ in range(3):  # transmission time from the geometric range
            rng_m = np.linalg.norm(_sagnac(st["pos_m"], 0.07) - rx, axis=1)
            st = satellite_states(eph_table, svs, np.full(svs.size, t), rng_m + C * st["clock_s"])
        sat = _sagnac(st["pos_m"], rng_m / C)
        los = sat - rx
        rng_m = np.linalg.norm(los, axis=1)
        u = los / rng_m[:, None]
        up = (R @ u.T).T[:, 2]
        keep = st["have"] & (up > np.sin(np.radians(10)))
        pr = rng_m + clock_m + drift_mps * k - C * st["clock_s"] + rng.normal(0, pr_noise_m, svs.size)
        prr = np.einsum("ij,ij->i", _sagnac(st["vel_mps"], rng_m / C) - v_ecef, u) + drift_mps - C * st["drift_sps"]
        dop = -prr * L1 / C + rng.normal(0, dop_noise_hz, svs.size)
        if doppler_fault_mps:
            dop = dop - doppler_fault_mps * L1 / C * np.dot(u, v_ecef / max(np.linalg.norm(v_ecef), 1e-9))
        idx = np.flatnonzero(keep)
        yield t, svs[idx], pr[idx], dop[idx]


def simulate_ubx(eph_table, t0_gps_s: float, n_epochs: int, lat_deg: float, lon_deg: float, h_m: float,
                 vel_enu_mps=(0.0, 0.0, 0.0), clock_m: float = 30_000.0, drift_mps: float = 120.0,
                 doppler_fault_mps: float = 0.0, with_sfrbx: bool = True, seed: int = 0,
                 pr_noise_m: float = 0.5, dop_noise_hz: float = 0.064) -> bytes:  # fmt: skip
    """A UBX byte stream: SFRBX navigation data of every GPS and Galileo satellite used, then one RAWX per second."""
    gps = eph_table[eph_table["sv"].str[0].isin(["G", "E"])]
    out = bytearray()
    used = set()
    rawx = []
    for t, svs, pr, dop in receiver_epochs(eph_table, t0_gps_s, n_epochs, lat_deg, lon_deg, h_m, vel_enu_mps, clock_m, drift_mps,
                                           doppler_fault_mps, seed, pr_noise_m, dop_noise_hz):  # fmt: skip
        used.update(svs.tolist())
        fields = {"rcvTow": round(t % WEEK_S, 3), "week": int(t // WEEK_S), "leapS": 18, "numMeas": svs.size}
        for j, (sv, p, d) in enumerate(zip(svs, pr, dop), start=1):
            s = f"_{j:02d}"
            fields.update({f"prMes{s}": float(p), f"cpMes{s}": 0.0, f"doMes{s}": float(d), f"gnssId{s}": GNSS_ID[sv[0]],
                           f"svId{s}": int(sv[1:]), f"sigId{s}": 0, f"freqId{s}": 0, f"locktime{s}": 10_000,
                           f"cno{s}": 42, f"prStd{s}": 5, f"cpStd{s}": 1, f"doStd{s}": 5, f"prValid{s}": 1})  # fmt: skip
        rawx.append(UBXMessage("RXM", "RXM-RAWX", GET, **fields).serialize())
    if with_sfrbx:
        week = int(t0_gps_s // WEEK_S)
        for sv in sorted(used):
            row = gps[gps["sv"] == sv].iloc[(gps[gps["sv"] == sv]["toc_s"] - t0_gps_s).abs().argmin()]
            iode = row.get("iode", np.nan)
            eph = {**row.to_dict(), "iode": int(row["IODE"] if np.isnan(float(iode)) else iode), "health": int(row["health"])}
            if sv.startswith("E"):
                for page in encode_pages(eph, t0_gps_s - 30):
                    out += UBXMessage("RXM", "RXM-SFRBX", GET, gnssId=2, svId=int(sv[1:]), sigId=1, numWords=8, version=2,
                                      **{f"dwrd_{i + 1:02d}": int(w) for i, w in enumerate(page)}).serialize()  # fmt: skip
                continue
            words = encode_subframes(eph, week, int(t0_gps_s % WEEK_S) - 30)
            for sub in words:
                out += UBXMessage("RXM", "RXM-SFRBX", GET, gnssId=0, svId=int(sv[1:]), sigId=0, numWords=10, version=2,
                                  **{f"dwrd_{i + 1:02d}": int(w) for i, w in enumerate(sub)}).serialize()  # fmt: skip
    for msg in rawx:
        out += msg
    return bytes(out)
