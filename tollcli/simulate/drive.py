"""A simulated drive: truth, what the receiver measures, and what it reports — as tables.

Chunks of epochs flow through: trajectory → sky (satellite geometry) → street
(line of sight) → errors (nominal, correlated, plus faults) → pseudoranges → the
receiver's WLS position (one clock per constellation, as a multi-GNSS receiver
estimates it), its residuals and DOPs. Each chunk gives two tables:

* epochs: one row per epoch — truth (``true_*``), the receiver's fix, DOPs,
  residual RMS and error ellipse, reported speed and course, the fault flag;
* satellites: one row per received (line-of-sight) satellite-epoch — angles,
  C/N0, ECEF at transmission, pseudorange, σ, nominal error, fault bias, residual.

Everything random comes from one seed through independent streams (street,
noise, faults, speed), so the same seed gives the same drive.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from tollcli.geodesy import ecef2geodetic, enu_rotation, enu_shift2geodetic
from tollcli.gnss.pseudorange_wls import line_of_sight as line_of_sight_ecef
from tollcli.gnss.pseudorange_wls import solve_positions
from tollcli.gnss.sigma_models import NominalModel
from tollcli.gnss.wls import observation_matrix, wls_geometry
from tollcli.simulate.constellations import nominal, stacked
from tollcli.simulate.errors import FaultPlan, fault_epochs, gauss_markov
from tollcli.simulate.route import Trajectory
from tollcli.simulate.sky import sky
from tollcli.simulate.streets import line_of_sight, make_street

#: the constellations' reference epoch: satellite geometry depends on the start time through it
GEOMETRY_EPOCH = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)


@dataclass
class SimConfig:
    constellations: list[str] = field(default_factory=lambda: ["gps", "galileo"])
    env: str = "urban"
    iono: str = "single"  # nominal error model: single | sbas | iono-free
    cn0_dbhz: float = 30.0  # the thesis's worst case, used for every satellite
    mask_deg: float = 5.0
    tc_s: float = 5.0
    faults: FaultPlan = field(default_factory=FaultPlan)
    seed: int = 0
    start_utc: dt.datetime = dt.datetime(2026, 3, 2, 8, 0, 0, tzinfo=dt.UTC)
    clock_bias_m: float = 12_345.0
    speed_sigma_mps: float = 0.05
    course_sigma_deg: float = 0.5
    max_per_constellation: int = 12  # receiver channels used per constellation (highest first)
    jam_at_s: list[float] = field(default_factory=list)  # jamming episodes: start times, s from the start
    jam_duration_s: float = 30.0
    jam_db: float = 0.0  # C/N0 loss of every satellite while jammed
    track_min_dbhz: float = 20.0  # satellites below this C/N0 are lost
    chunk_epochs: int = 3600
    nav_path: str | None = None  # RINEX navigation file: broadcast orbits instead of the nominal constellations
    lateral_bias_m: float = 0.0  # a receiver-level position offset to the right of travel (invisible to RAIM) …
    lateral_bias_at_s: list[float] = field(default_factory=list)  # … from these times …
    lateral_bias_duration_s: float = 60.0  # … for this long
    # a city street's reflections (off by default): a satellite the buildings block is received by reflection part of
    # the time, weaker (C/N0) and late (a positive excess path), both correlated over ``nlos_tc_s``; the LOS C/N0 then
    # rises with elevation (cn0_dbhz at the horizon, + 15 dB at the zenith)
    nlos: bool = False
    nlos_tc_s: float = 30.0
    # the vehicle's odometry (off by default): wheel speed with a scale error, yaw rate with a bias, each with noise
    odometry: bool = False
    odo_scale: float = 0.01
    odo_speed_sigma_mps: float = 0.05
    gyro_bias_radps: float = 0.002
    gyro_sigma_radps: float = 0.002
    # sensor faults (the odometry's own): from these times, for ``sensor_fault_duration_s``, the odometer's scale is
    # off by a further ``odo_scale_step`` (a slipping wheel, a wrong tyre) and the gyro by a further ``gyro_bias_step_radps``
    sensor_fault_at_s: list[float] = field(default_factory=list)
    sensor_fault_duration_s: float = 60.0
    odo_scale_step: float = 0.0
    gyro_bias_step_radps: float = 0.0


@dataclass
class SimChunk:
    epochs: pd.DataFrame
    satellites: pd.DataFrame


def _streams(seed: int) -> dict[str, np.random.Generator]:
    names = ("street", "noise", "faults", "speed", "nlos", "odometry")  # (added at the end: the first streams stay as they were)
    return dict(zip(names, (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(len(names)))))


def _top_k(elev: np.ndarray, visible: np.ndarray, group: np.ndarray, k: int) -> np.ndarray:
    """Keep, per epoch and constellation, the ``k`` highest visible satellites."""
    keep = visible.copy()
    for g in np.unique(group):
        cols = np.flatnonzero(group == g)
        score = np.where(visible[:, cols], elev[:, cols], -np.inf)
        rank = np.argsort(np.argsort(-score, axis=1, kind="stable"), axis=1, kind="stable")
        keep[:, cols] &= rank < k
    return keep


def simulate(traj: Trajectory, config: SimConfig) -> Iterator[SimChunk]:
    """The drive, chunk by chunk."""
    if config.nav_path:
        from tollcli.simulate.broadcast_orbits import gps_seconds_of, load_orbits

        sats = load_orbits(config.nav_path, config.constellations)
        names, svid = sats.names, sats.svid
        t_geo = gps_seconds_of(pd.Timestamp(config.start_utc))
    else:
        names, svid, sats = stacked(nominal(config.constellations))
        t_geo = (config.start_utc - GEOMETRY_EPOCH).total_seconds()
    group = np.unique(names, return_inverse=True)[1]
    rng = _streams(config.seed)
    length = float(traj.s_m[-1]) if traj.s_m.size else 0.0
    street = make_street(config.env, length, rng["street"])
    model = NominalModel(iono=config.iono, default_cn0_dbhz=config.cn0_dbhz)
    faulty_all = fault_epochs(config.faults, traj.t_s, rng["faults"])
    dt_s = float(np.median(np.diff(traj.t_s))) if traj.t_s.size > 1 else 1.0
    yaw_radps = _yaw_rate_radps(traj) if config.odometry else None
    state = nlos_state = None
    start = pd.Timestamp(config.start_utc)
    for lo in range(0, traj.t_s.size, config.chunk_epochs):
        sl = slice(lo, min(lo + config.chunk_epochs, traj.t_s.size))
        t = traj.t_s[sl]
        n = t.size
        lat, lon, h = traj.lat_deg[sl], traj.lon_deg[sl], traj.height_m[sl]
        view = sky(sats, t_geo + t, lat, lon, h)
        elev, azim = view["elev_deg"], view["azim_deg"]
        visible = (elev >= config.mask_deg) & line_of_sight(street, traj.s_m[sl], traj.heading_deg[sl], elev, azim)
        jammed = np.zeros(n, bool)
        for j0 in config.jam_at_s:  # a few episodes
            jammed |= (t >= j0) & (t < j0 + config.jam_duration_s)
        cn0 = np.full(elev.shape, config.cn0_dbhz) - np.where(jammed, config.jam_db, 0.0)[:, None]
        excess = np.zeros(elev.shape)
        if config.nlos:
            reflected, cn0, excess, nlos_state = _reflections(config, elev, visible, cn0, dt_s, rng["nlos"], nlos_state)
            visible |= reflected
        visible &= cn0 >= config.track_min_dbhz
        used = _top_k(elev, visible, group, config.max_per_constellation)
        sigma = model.sigma_m(elev, cn0, names[None, :], lat[:, None], lon[:, None])
        unit, state = gauss_markov(n, names.size, config.tc_s, dt_s, rng["noise"], state)
        error = sigma * unit + excess  # (with reflections: the excess path of a reflected signal)
        H = observation_matrix(elev, azim, np.broadcast_to(group, elev.shape), int(group.max()) + 1)
        geometry = wls_geometry(H, np.where(used, sigma, np.nan), used)
        faulty = faulty_all[sl]
        bias = np.zeros(elev.shape)
        fault_col = _fault_column(config.faults, names, svid, geometry.slope, used)
        rows = np.flatnonzero(faulty & (fault_col >= 0))
        bias[rows, fault_col[rows]] = config.faults.bias_m
        pr = view["range_m"] + config.clock_bias_m + error + bias
        measured = ChunkMeasurements(first_epoch=lo, t_s=t, rows=sl, view=view, used=used, cn0_dbhz=cn0, sigma_m=sigma, error_m=error,
                                     bias_m=bias, pr_m=pr, faulty=faulty, fault_col=fault_col)  # fmt: skip
        chunk = _receiver_output(measured, Satellites(names, svid, group), traj, start, config, rng)
        if yaw_radps is not None:  # the odometer and the gyro: what the vehicle's own sensors say
            o = rng["odometry"]
            broken = sensor_fault(config, t)
            scale = 1.0 + config.odo_scale + np.where(broken, config.odo_scale_step, 0.0)
            gyro_bias = config.gyro_bias_radps + np.where(broken, config.gyro_bias_step_radps, 0.0)
            chunk.epochs["odo_speed_mps"] = traj.speed_mps[sl] * scale + config.odo_speed_sigma_mps * o.standard_normal(n)
            chunk.epochs["odo_yaw_rate_radps"] = yaw_radps[sl] + gyro_bias + config.gyro_sigma_radps * o.standard_normal(n)
        yield chunk


def sensor_fault(config: SimConfig, t_s: np.ndarray) -> np.ndarray:
    """Whether the odometry is faulty (``sensor_fault_at_s``, for ``sensor_fault_duration_s``) at times ``t_s`` (s)."""
    broken = np.zeros(t_s.size, bool)
    for at in config.sensor_fault_at_s:  # a few episodes
        broken |= (t_s >= at) & (t_s < at + config.sensor_fault_duration_s)
    return broken


def _yaw_rate_radps(traj: Trajectory) -> np.ndarray:
    """The true yaw rate (rad/s, counter-clockwise positive as a gyro's z axis) from the heading (clockwise from north)."""
    if traj.t_s.size < 2:
        return np.zeros(traj.t_s.size)
    return -np.gradient(np.unwrap(np.radians(traj.heading_deg)), traj.t_s)


def _reflections(config: SimConfig, elev: np.ndarray, line_of_sight_ok: np.ndarray, cn0: np.ndarray, dt_s: float,
                 rng: np.random.Generator, state) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Which blocked satellites are received by reflection (about 60 % of the time, in spells of ``nlos_tc_s``), every
    satellite's C/N0 (LOS: + 15 dB·sin(elevation); reflected: 8–18 dB weaker) and the reflected signals' excess path
    (m, ≥ 5, growing with the loss: ~30–70 m), from three correlated unit processes per satellite."""
    n, m = elev.shape
    u, last = gauss_markov(n, 3 * m, config.nlos_tc_s, dt_s, rng, state)
    present, loss, spread = u[:, :m], u[:, m : 2 * m], u[:, 2 * m :]
    above = elev >= config.mask_deg
    reflected = above & ~line_of_sight_ok & (present > -0.25)
    loss_db = np.clip(13.0 + 3.0 * loss, 8.0, 18.0)
    los_cn0 = cn0 + 15.0 * np.sin(np.radians(np.clip(elev, 0.0, 90.0)))
    cn0 = np.where(reflected, los_cn0 - loss_db, los_cn0)
    excess = np.where(reflected, np.maximum(5.0, 4.0 * (loss_db - 5.0) + 15.0 * np.abs(spread)), 0.0)
    return reflected, cn0, excess, last


def _fault_column(plan: FaultPlan, names: np.ndarray, svid: np.ndarray, slope: np.ndarray, used: np.ndarray) -> np.ndarray:
    """Per epoch, the column of the satellite that carries the fault (−1: none visible)."""
    if plan.sv:
        letter = {"G": "GPS", "E": "Galileo"}.get(plan.sv[0].upper())
        match = np.flatnonzero((names == letter) & (svid == int(plan.sv[1:])))
        if match.size == 0:
            raise ValueError(f"fault satellite {plan.sv!r} is not in the simulated constellations")
        return np.where(used[:, match[0]], match[0], -1)
    finite = np.where(used & np.isfinite(slope), slope, -np.inf)
    col = np.argmax(finite, axis=1)
    return np.where(np.isfinite(finite.max(axis=1, initial=-np.inf)), col, -1)


@dataclass(frozen=True)
class Satellites:
    """The simulated satellites (one entry each): constellation name, PRN, receiver clock group."""

    names: np.ndarray
    svid: np.ndarray
    group: np.ndarray


@dataclass(frozen=True)
class ChunkMeasurements:
    """What the receiver measured over a stretch of epochs (arrays epochs × satellites)."""

    first_epoch: int  # the stretch's first epoch number in the drive
    t_s: np.ndarray  # its epochs' times, s from the start
    rows: slice  # its epochs in the trajectory
    view: dict  # the sky: satellite ECEF at transmission, ranges, elevations, azimuths
    used: np.ndarray  # received and used in the fix
    cn0_dbhz: np.ndarray
    sigma_m: np.ndarray
    error_m: np.ndarray  # the nominal (correlated) error
    bias_m: np.ndarray  # the fault bias
    pr_m: np.ndarray  # the pseudorange the receiver measured
    faulty: np.ndarray  # per epoch: a fault episode is on
    fault_col: np.ndarray  # per epoch: the faulty satellite's column (−1: none)


def _receiver_output(m: ChunkMeasurements, sats: Satellites, traj: Trajectory, start: pd.Timestamp, config: SimConfig,
                     rng: dict) -> SimChunk:  # fmt: skip
    """What the receiver reports of a stretch: its WLS fix, residuals, DOPs, error ellipse, speed and course."""
    lo, t, sl = m.first_epoch, m.t_s, m.rows
    names, svid, group = sats.names, sats.svid, sats.group
    view, used, cn0, sigma, error, bias, pr = m.view, m.used, m.cn0_dbhz, m.sigma_m, m.error_m, m.bias_m, m.pr_m
    faulty, fault_col = m.faulty, m.fault_col
    n = t.size
    n_groups = int(group.max()) + 1
    clock_index = np.broadcast_to(group, used.shape)
    x = solve_positions(view["sat_xyz"], np.where(used, pr, 0.0), used, np.where(used, sigma, np.nan), clock_index=clock_index)
    lat, lon, hgt = ecef2geodetic(x[:, 0], x[:, 1], x[:, 2])
    if config.lateral_bias_m and config.lateral_bias_at_s:
        on = np.zeros(n, bool)
        for b0 in config.lateral_bias_at_s:  # a few episodes
            on |= (t >= b0) & (t < b0 + config.lateral_bias_duration_s)
        right = np.radians(traj.heading_deg[sl] + 90.0)
        shift = np.where(on, config.lateral_bias_m, 0.0)
        lat, lon = enu_shift2geodetic(lat, lon, shift * np.sin(right), shift * np.cos(right))
    # residuals and DOPs at the solution
    los, rng_m = line_of_sight_ecef(view["sat_xyz"], x)
    clk = np.take_along_axis(x[:, 3:], clock_index, axis=1)
    residual_pre = np.where(used, pr - (rng_m + clk), np.nan)
    R = enu_rotation(lat, lon)
    los_enu = np.einsum("eij,enj->eni", R, los)
    H = np.concatenate([-los_enu, (clock_index[..., None] == np.arange(n_groups)).astype(float)], axis=-1)
    geometry = wls_geometry(H, np.where(used, sigma, np.nan), used)
    dx = np.einsum("eun,en->eu", geometry.A, np.nan_to_num(residual_pre))
    residual = np.where(used, residual_pre - np.einsum("enu,eu->en", H, dx), np.nan)
    fix = ~geometry.singular & (geometry.dof >= 0) & (geometry.n_meas >= 4)
    dop = _dops(H, used, fix)
    cov_en = _en_covariance(geometry, sigma, used)
    major, minor, orient = _ellipse(cov_en)
    sq = np.where(used, residual, 0.0) ** 2
    n_res = used.sum(axis=1)
    rms = np.where(n_res > 0, np.sqrt(sq.sum(axis=1) / np.maximum(n_res, 1)), np.nan)
    speed = np.abs(traj.speed_mps[sl] + config.speed_sigma_mps * rng["speed"].standard_normal(n))  # a speed is ≥ 0
    course = (traj.heading_deg[sl] + config.course_sigma_deg * rng["speed"].standard_normal(n)) % 360.0
    times = start + pd.to_timedelta(np.round(t * 1000).astype(np.int64), unit="ms")
    nan = np.nan
    epochs = pd.DataFrame({
        "epoch": np.arange(lo, lo + n, dtype=np.int64),
        "t_s": t,
        "time_utc": times,
        "true_lat_deg": traj.lat_deg[sl], "true_lon_deg": traj.lon_deg[sl], "true_height_m": traj.height_m[sl],
        "true_heading_deg": traj.heading_deg[sl], "true_speed_mps": traj.speed_mps[sl], "s_m": traj.s_m[sl],
        "fix": fix,
        "lat_deg": np.where(fix, lat, nan), "lon_deg": np.where(fix, lon, nan), "height_m": np.where(fix, hgt, nan),
        "n_used": used.sum(axis=1).astype(np.int16),
        "pdop": dop[:, 0], "hdop": dop[:, 1], "vdop": dop[:, 2],
        "rms_residual_m": np.where(fix, rms, nan),
        "sigma_major_m": major, "sigma_minor_m": minor, "ellipse_orient_deg": orient,
        "sigma_lat_m": np.sqrt(cov_en[:, 1, 1]), "sigma_lon_m": np.sqrt(cov_en[:, 0, 0]),
        "speed_mps": speed, "course_deg": course,
        "faulty": faulty & (fault_col >= 0),
    })  # fmt: skip
    e_idx, s_idx = np.nonzero(used)
    satellites = pd.DataFrame({
        "epoch": lo + e_idx,
        "constellation": names[s_idx],
        "svid": svid[s_idx].astype(np.int16),
        "elev_deg": view["elev_deg"][e_idx, s_idx], "azim_deg": view["azim_deg"][e_idx, s_idx],
        "cn0_dbhz": cn0[e_idx, s_idx],
        "x_sv_m": view["sat_xyz"][e_idx, s_idx, 0], "y_sv_m": view["sat_xyz"][e_idx, s_idx, 1], "z_sv_m": view["sat_xyz"][e_idx, s_idx, 2],
        "pr_m": pr[e_idx, s_idx], "sigma_m": sigma[e_idx, s_idx], "error_m": error[e_idx, s_idx], "fault_m": bias[e_idx, s_idx],
        "residual_m": residual[e_idx, s_idx],
    })  # fmt: skip
    return SimChunk(epochs, satellites)


def _dops(H: np.ndarray, used: np.ndarray, fix: np.ndarray) -> np.ndarray:
    """(E, 3) PDOP, HDOP, VDOP from the unweighted geometry (NaN without a fix)."""
    g = wls_geometry(H, np.where(used, 1.0, np.nan), used)
    # unweighted covariance (HᵀH)⁻¹ = A·Aᵀ
    cov = np.einsum("eun,evn->euv", g.A, g.A)
    e, nn, u = cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2]
    out = np.stack([np.sqrt(e + nn + u), np.sqrt(e + nn), np.sqrt(u)], axis=1)
    return np.where(fix[:, None], out, np.nan)


def _en_covariance(geometry, sigma: np.ndarray, used: np.ndarray) -> np.ndarray:
    """(E, 2, 2) east-north covariance of the WLS position, m²."""
    A = geometry.A[:, :2, :]
    var = np.where(used, sigma, 0.0) ** 2
    return np.einsum("eun,en,evn->euv", A, var, A)


def _ellipse(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1σ semi-axes and orientation of the major axis (degrees from true north)."""
    w, v = np.linalg.eigh(cov)
    major = np.sqrt(np.maximum(w[:, 1], 0.0))
    minor = np.sqrt(np.maximum(w[:, 0], 0.0))
    orient = np.degrees(np.arctan2(v[:, 0, 1], v[:, 1, 1])) % 180.0
    return major, minor, orient
