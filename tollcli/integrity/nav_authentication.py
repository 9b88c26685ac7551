"""Whether each position rests on authenticated navigation data (Galileo OSNMA), and the position from
authenticated satellites only with its distance to the full solution.

Inputs: the epoch's measurement slots (:class:`~tollcli.gnss.measurements.Measurements`: the satellites the
fix used, their geometry, σ and the receiver's residuals) and, per slot, whether that satellite's navigation
data were authenticated at the epoch (:func:`authenticated_slots`, from
:mod:`tollcli.gnss.osnma.satellite_status`).

The position from the authenticated satellites alone is the weighted least-squares solution over that subset,
linearised at the receiver's fix with the receiver's own residuals r (the ranges themselves are not in a
navigation log): x_auth = x_rx + A_auth·r, the full solution x_rx + A_all·r, so their separation is
(A_auth − A_all)·r — exact to first order for a least-squares receiver (a Kalman filter's residuals make it
the separation between the two snapshot solutions). Under no fault the separation has covariance
P_auth − P_all (nested WLS), so ``auth_sep_threshold_m`` = σ_major·√χ²₂(1 − p_fa) bounds its horizontal
length with probability ≥ 1 − p_fa.

``nav_auth`` per epoch (:data:`NAV_AUTH_STATUSES`):

authenticated
  every satellite the fix used had authenticated data (the position is the authenticated one);
authenticated_subset
  ≥ 4 used satellites had, their position is computable and lies within the threshold of the full one;
subset_disagrees
  the authenticated satellites' position is further than the threshold from the full one (the others pull it);
unauthenticated
  fewer than 4 used satellites authenticated, their geometry is singular, or there are no residuals to
  compare the two solutions with;
not_checked
  no OSNMA evidence for the log (no Galileo pages, or no Merkle tree to verify them against).

:data:`ACCEPTED` are those a ``--require-authenticated`` charge accepts.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from tollcli.geodesy import enu_shift2geodetic
from tollcli.gnss.measurements import Measurements, sv_labels
from tollcli.gnss.wls import Geometry, wls_geometry

NAV_AUTH_STATUSES = ("authenticated", "authenticated_subset", "subset_disagrees", "unauthenticated", "not_checked")
ACCEPTED = ("authenticated", "authenticated_subset")
#: satellites with authenticated data needed for a position of their own (3 coordinates and a clock)
MIN_AUTHENTICATED = 4
#: what each status means, for an invoice's notes (a position not charged under --require-authenticated says why)
STATUS_NOTES = {
    "unauthenticated": "fewer than 4 satellites the fix used had navigation data authenticated by Galileo OSNMA "
                       "(or the log carries no Galileo navigation pages to authenticate)",
    "subset_disagrees": "the position from the satellites with authenticated navigation data lies further from the "
                        "receiver's fix than the no-fault bound (auth_sep_threshold_m)",
}  # fmt: skip


def authenticated_satellites(status: pd.DataFrame) -> pd.DataFrame:
    """(``time_utc``, ``sv``) of the rows of a per-epoch-and-satellite status table (``time_utc``,
    ``constellation``, ``svid``, ``nav_authenticated``) whose data were authenticated: what
    :func:`epoch_authentication` looks up."""
    auth = status[status["nav_authenticated"].to_numpy(bool)]
    return pd.DataFrame({"time_utc": auth["time_utc"].array,  # (the times kept as times: no array of Timestamp objects)
                         "sv": sv_labels(auth["constellation"].to_numpy(object), auth["svid"].to_numpy())})  # fmt: skip


def epoch_authentication(meas: Measurements, epochs: pd.DataFrame, authenticated: pd.DataFrame, p_fa: float = 5e-3,
                         geometry: Geometry | None = None) -> pd.DataFrame:  # fmt: skip
    """:func:`authenticated_positions` of ``epochs`` (``time_utc``, ``lat_deg``, ``lon_deg``; the rows of ``meas``)
    with the satellites :func:`authenticated_satellites` lists (``geometry``: the full solution's, when at hand)."""
    auth = authenticated_slots(meas.sv, epochs["time_utc"], authenticated)
    return authenticated_positions(meas, auth, epochs["lat_deg"].to_numpy(float), epochs["lon_deg"].to_numpy(float), p_fa, geometry)


def authenticated_slots(sv: np.ndarray, time_utc: pd.Series, authenticated: pd.DataFrame) -> np.ndarray:
    """(E, N) bool: the slot's satellite (label ``sv`` such as "E11") had authenticated data at the epoch.

    ``time_utc``: the E epochs' times; ``authenticated``: rows (``time_utc``, ``sv``) of satellites whose
    data were authenticated then (any other slot is not).
    """
    n_epochs, n_slots = sv.shape
    if n_epochs == 0 or n_slots == 0 or len(authenticated) == 0:
        return np.zeros(sv.shape, bool)
    t_ns = pd.to_datetime(time_utc, utc=True).dt.tz_convert(None).to_numpy("datetime64[ns]").astype(np.int64)
    rows, slots = np.nonzero(sv != "")
    wanted = pd.DataFrame({"t": t_ns[rows], "sv": sv[rows, slots]})
    have = pd.DataFrame({"t": pd.to_datetime(authenticated["time_utc"], utc=True).dt.tz_convert(None)
                         .to_numpy("datetime64[ns]").astype(np.int64), "sv": authenticated["sv"].to_numpy(object), "hit": True})  # fmt: skip
    hit = wanted.merge(have.drop_duplicates(["t", "sv"]), on=["t", "sv"], how="left")["hit"].fillna(False).to_numpy(bool)
    out = np.zeros(sv.shape, bool)
    out[rows, slots] = hit
    return out


def _horizontal_major_sigma(cov: np.ndarray) -> np.ndarray:
    """Largest standard deviation of the horizontal (east, north) block of (E, U, U) covariances, m."""
    a, b, c = cov[:, 0, 0], cov[:, 1, 1], cov[:, 0, 1]
    major = (a + b) / 2 + np.sqrt(np.maximum(((a - b) / 2) ** 2 + c**2, 0.0))
    return np.sqrt(np.maximum(major, 0.0))


def authenticated_positions(meas: Measurements, auth: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray,
                            p_fa: float = 5e-3, geometry: Geometry | None = None) -> pd.DataFrame:  # fmt: skip
    """Per epoch: ``nav_auth``, ``n_used_slots``, ``n_used_authenticated``, the authenticated-only position
    (``auth_lat_deg``, ``auth_lon_deg``), its horizontal distance to the full solution ``auth_sep_m`` and the
    no-fault bound on that distance ``auth_sep_threshold_m`` (module docstring). ``auth``: (E, N) from
    :func:`authenticated_slots`; ``lat_deg``/``lon_deg``: the receiver's fixes (the full solution); ``geometry``: the
    full solution's :func:`~tollcli.gnss.wls.wls_geometry` when the caller has it."""

    mask = meas.mask
    sub = mask & auth
    n_used, n_auth = mask.sum(axis=1), sub.sum(axis=1)
    full_geom = geometry if geometry is not None else wls_geometry(meas.H, meas.sigma_m, mask)
    sub_geom = wls_geometry(meas.H, meas.sigma_m, sub)
    r = meas.residual_m if meas.residual_m is not None else np.full(mask.shape, np.nan)
    have_r = ~(mask & ~np.isfinite(r)).any(axis=1) & mask.any(axis=1)
    r0 = np.where(mask & np.isfinite(r), r, 0.0)
    sep = np.einsum("eun,en->eu", sub_geom.A - full_geom.A, r0)
    var = np.where(sub, meas.sigma_m, 0.0) ** 2
    var_full = np.where(mask, meas.sigma_m, 0.0) ** 2
    cov = np.einsum("eun,en,evn->euv", sub_geom.A, var, sub_geom.A) - np.einsum("eun,en,evn->euv", full_geom.A, var_full, full_geom.A)
    threshold = _horizontal_major_sigma(cov) * np.sqrt(-2.0 * np.log(p_fa))  # χ²₂'s (1 − p_fa) quantile, in closed form
    computable = (n_auth >= MIN_AUTHENTICATED) & ~sub_geom.singular & have_r
    sep_m = np.where(computable, np.hypot(sep[:, 0], sep[:, 1]), np.nan)
    threshold = np.where(computable, threshold, np.nan)
    all_used = (n_used > 0) & (n_auth == n_used)
    status = np.where(all_used, "authenticated", "unauthenticated").astype(object)
    partial = ~all_used & computable
    # a rounding margin: the two solutions of a subset equal to the whole differ by float noise only
    agrees = sep_m <= threshold + 1e-6
    status[partial & agrees] = "authenticated_subset"
    status[partial & ~agrees] = "subset_disagrees"
    east = np.where(all_used, 0.0, np.where(computable, sep[:, 0], np.nan))
    north = np.where(all_used, 0.0, np.where(computable, sep[:, 1], np.nan))
    auth_lat, auth_lon = enu_shift2geodetic(np.asarray(lat_deg, float), np.asarray(lon_deg, float), east, north)
    return pd.DataFrame({"nav_auth": status, "n_used_slots": n_used, "n_used_authenticated": n_auth,
                         "auth_lat_deg": auth_lat, "auth_lon_deg": auth_lon,
                         "auth_sep_m": np.where(all_used, 0.0, sep_m), "auth_sep_threshold_m": threshold})  # fmt: skip


def not_checked(n_epochs: int) -> pd.DataFrame:
    """The columns of :func:`authenticated_positions` for epochs without OSNMA evidence."""
    nan = np.full(n_epochs, np.nan)
    return pd.DataFrame({"nav_auth": np.full(n_epochs, "not_checked", dtype=object), "n_used_slots": np.zeros(n_epochs, np.int64),
                         "n_used_authenticated": np.zeros(n_epochs, np.int64), "auth_lat_deg": nan, "auth_lon_deg": nan.copy(),
                         "auth_sep_m": nan.copy(), "auth_sep_threshold_m": nan.copy()})  # fmt: skip


def require_authenticated(epoch_why: np.ndarray | None, nav_auth: np.ndarray) -> np.ndarray:
    """The policy's failed check per epoch ('' when none) with authentication as one more condition: an epoch
    whose ``nav_auth`` is not :data:`ACCEPTED` fails with its status (``unauthenticated``, ``subset_disagrees``,
    ``not_checked`` becomes ``unauthenticated``)."""
    nav_auth = np.asarray(nav_auth, dtype=object)
    why = np.full(nav_auth.size, "", dtype=object) if epoch_why is None else np.asarray(epoch_why, dtype=object).copy()
    fails = (why == "") & ~np.isin(nav_auth, ACCEPTED)
    why[fails] = np.where(nav_auth[fails] == "subset_disagrees", "subset_disagrees", "unauthenticated")
    return why
