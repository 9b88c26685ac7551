"""Broadcast atmospheric corrections for single-frequency pseudoranges (delays in metres).

* Ionosphere: GPS Klobuchar (IS-GPS-200 §20.3.3.5.2.5) from the eight broadcast
  coefficients; applied to Galileo E1 as well (same carrier frequency as L1) in
  place of NeQuick, which a log processor rarely has — the nominal error model
  bounds what is left.
* Troposphere: Saastamoinen with a standard atmosphere (as RTKLIB's
  ``tropmodel``: 1013.25 hPa and 15 °C at sea level, 70 % humidity).
"""

from __future__ import annotations

import numpy as np

C_MPS = 299_792_458.0


def klobuchar_delay_m(lat_deg, lon_deg, elev_deg, azim_deg, gps_tow_s, alpha, beta) -> np.ndarray:
    """L1 ionospheric delay (m) from the Klobuchar model; inputs broadcast."""
    alpha, beta = np.asarray(alpha, float), np.asarray(beta, float)
    el = np.asarray(elev_deg, float) / 180.0  # semicircles
    az = np.radians(azim_deg)
    psi = 0.0137 / (el + 0.11) - 0.022
    phi_i = np.clip(np.asarray(lat_deg, float) / 180.0 + psi * np.cos(az), -0.416, 0.416)
    lam_i = np.asarray(lon_deg, float) / 180.0 + psi * np.sin(az) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)
    t = np.mod(4.32e4 * lam_i + np.asarray(gps_tow_s, float), 86_400.0)
    amp = np.maximum(sum(alpha[n] * phi_m**n for n in range(4)), 0.0)
    per = np.maximum(sum(beta[n] * phi_m**n for n in range(4)), 72_000.0)
    x = 2 * np.pi * (t - 50_400.0) / per
    f = 1.0 + 16.0 * (0.53 - el) ** 3
    delay_s = np.where(np.abs(x) < 1.57, f * (5e-9 + amp * (1 - x**2 / 2 + x**4 / 24)), f * 5e-9)
    return C_MPS * delay_s


def saastamoinen_delay_m(lat_deg, height_m, elev_deg, humidity: float = 0.7) -> np.ndarray:
    """Tropospheric delay (m), standard atmosphere; 0 below the horizon or outside −100 m…10 km."""
    el = np.radians(np.asarray(elev_deg, float))
    h = np.asarray(height_m, float)
    hgt = np.maximum(h, 0.0)
    pres = 1013.25 * (1 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    cos_z = np.cos(np.pi / 2 - el)
    lat = np.radians(lat_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        dry = 0.0022768 * pres / (1 - 0.00266 * np.cos(2 * lat) - 0.00028 * hgt / 1e3) / cos_z
        wet = 0.002277 * (1255.0 / temp + 0.05) * e / cos_z
    ok = (el > 0) & (h > -100.0) & (h < 1e4)
    return np.where(ok, dry + wet, 0.0)
