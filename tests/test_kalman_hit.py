"""Paper 004's indicators: HIT through an outage on a simulated drive, and HPL_SBAS."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tollcli.geodesy import enu_rotation, geodetic2ecef
from tollcli.gnss.wls import observation_matrix, wls_geometry
from tollcli.integrity.kalman_hit import K_H_SBAS, hit, hpl_sbas_m
from tollcli.simulate.drive import SimConfig, simulate
from tollcli.simulate.route import straight


def _enu(lat, lon, lat0, lon0):
    d = np.stack(geodetic2ecef(np.asarray(lat), np.asarray(lon), 0.0), -1) - np.stack(geodetic2ecef(lat0, lon0, 0.0), -1)
    enu = np.einsum("ij,ej->ei", enu_rotation(lat0, lon0), d)
    return enu[:, 0], enu[:, 1]


def test_hit_grows_through_an_outage_and_bounds_the_errors():
    traj = straight(42.6, 2.88, 60.0, 13.89, 900)
    # a 30 s total outage (every satellite jammed) at t = 400 s; white errors (the filter's assumption)
    chunks = list(simulate(traj, SimConfig(env="open", seed=5, tc_s=0.0, jam_at_s=[400.0], jam_duration_s=30.0, jam_db=40.0)))
    ep = pd.concat([c.epochs for c in chunks], ignore_index=True)
    lat0, lon0 = ep["true_lat_deg"].iloc[0], ep["true_lon_deg"].iloc[0]
    e, n = _enu(ep["lat_deg"].fillna(lat0), ep["lon_deg"].fillna(lon0), lat0, lon0)
    e[~ep["fix"].to_numpy()] = np.nan
    n[~ep["fix"].to_numpy()] = np.nan
    te, tn = _enu(ep["true_lat_deg"], ep["true_lon_deg"], lat0, lon0)
    sigma = ep["sigma_major_m"].to_numpy()
    out = hit(e, n, np.where(ep["fix"], ep["speed_mps"], np.nan), ep["t_s"].to_numpy(), sigma)
    h = out["hit_m"].to_numpy()
    outage = np.flatnonzero(~ep["fix"].to_numpy())
    assert outage.size >= 29
    # HIT grows through the outage and shrinks after it
    assert np.all(np.diff(h[outage]) > 0)
    assert h[outage[-1]] > 2 * h[outage[0] - 1]
    assert h[outage[-1] + 30] < 0.5 * h[outage[-1]]
    # true errors stay within HIT at the stated rate (3σ of the ellipse's major axis: ≥ 98.9 %)
    err = np.hypot(out["kf_east_m"] - te, out["kf_north_m"] - tn).to_numpy()
    inside = err[20:] <= h[20:]
    assert inside.mean() >= 0.985
    assert (err[outage] <= h[outage]).all()


def test_hpl_sbas_is_k_h_times_the_major_semi_axis():
    # four satellites in a square at 45° elevation plus zenith, σ 1 m: the covariance is isotropic
    elev = np.array([[45.0, 45.0, 45.0, 45.0, 90.0]])
    azim = np.array([[0.0, 90.0, 180.0, 270.0, 0.0]])
    H = observation_matrix(elev, azim, np.zeros((1, 5), dtype=np.int64), 1)
    sigma = np.ones((1, 5))
    g = wls_geometry(H, sigma, np.ones((1, 5), bool))
    cov = np.linalg.inv(H[0].T @ H[0])
    assert hpl_sbas_m(g, sigma)[0] == pytest.approx(K_H_SBAS * np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]))))
    # doubling every σ doubles it
    assert hpl_sbas_m(wls_geometry(H, 2 * sigma, np.ones((1, 5), bool)), 2 * sigma)[0] == pytest.approx(2 * hpl_sbas_m(g, sigma)[0])
