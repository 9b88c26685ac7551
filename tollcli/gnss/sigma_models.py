"""Pseudorange error models: σ per measurement, in metres (thesis §4.3, ALGORITHMS.md §5).

Three choices (``--sigma-model``):

* ``constant``: the same σ for every measurement (``--sigma``);
* ``input``: the σ the log reports per measurement (e.g. GSDC ``rawPrUncM``);
* ``nominal``: the thesis's overbounding model,
  σ² = σ_clk&eph² + σ_iono² + σ_tropo² + σ_noise² + σ_mp², with
  - clock & ephemeris 0.85 m (modernised GPS / Galileo, the thesis's simulations); GLONASS 2.8 m and BeiDou 1.4 m,
    the same 1.4× over the broadcast orbits' and clocks' measured global RMS (Montenbruck, Steigenberger & Hauschild
    2018, Adv. Space Res. 61(12): 0.6 m GPS, 2 m GLONASS, 1 m BeiDou-2) as 0.85 m is over GPS's;
  - ionosphere, single frequency: F·τ_v, τ_v = 9 / 4.5 / 6 m by geomagnetic latitude
    (≤ 20°, 20–55°, > 55°); ``sbas``: F·0.46 m; ``iono-free``: 0, with noise and
    multipath of the two bands scaled by k_A² = 5.11, k_B² = 1.59 (L1/E1 + L5/E5a);
  - troposphere DO-229: 0.12·1.001/√(0.002001 + sin²θ) m;
  - thermal noise of a 1 Hz dot-product DLL with 20 ms integration (Betz), from C/N0
    (30 dB-Hz, the thesis's worst case, where the log has none);
  - multipath, the thesis's urban overbound (Table 4.3, 20 ms), independent of
    elevation: wideband C/A 0.41 m, BPSK(10) 0.22 m, BOC(1,1) 0.53 m.
  The thesis applies the same nominal model in urban and rural streets (the
  environments differ in which satellites are visible), so ``urban`` and
  ``rural`` name the same model. NLOS signals are faults, not nominal errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

C_MPS = 299_792_458.0
CHIP_RATE_HZ = 1.023e6
EARTH_RADIUS_M = 6_378_136.3
IONO_HEIGHT_M = 350_000.0
L5_IONO_FACTOR = 1.79  # (f_L1 / f_L5)²
KA2_L1L5 = 5.11
KB2_L1L5 = 1.59
SIGMA_MODELS = ("nominal", "urban", "rural", "constant", "input")

#: receiver front ends (thesis Table 3.3): PSD, two-sided bandwidth (Hz), early-late spacing (chips), chip-rate multiple
SIGNALS = {
    "bpsk1_narrow": ("bpsk", 2e6, 1.0, 1),
    "bpsk1_wide": ("bpsk", 16e6, 0.1, 1),
    "bpsk10": ("bpsk", 20e6, 0.25, 10),
    "boc11": ("boc11", 4e6, 0.2, 1),
}
#: multipath 1σ (thesis Table 4.3, T_I = 20 ms); narrowband C/A is given only as a figure: the wideband value is used
MULTIPATH_M = {"bpsk1_narrow": 0.41, "bpsk1_wide": 0.41, "bpsk10": 0.22, "boc11": 0.53}
DEFAULT_SIGNALS = {
    "GPS": "bpsk1_wide", "GLONASS": "bpsk1_wide", "Galileo": "boc11", "BeiDou": "bpsk1_wide",
    "QZSS": "bpsk1_wide", "NavIC": "bpsk1_wide", "SBAS": "bpsk1_wide", "unknown": "bpsk1_wide",
}  # fmt: skip


#: clock & ephemeris σ (m) where it is not :attr:`NominalModel.clk_eph_m`
CLK_EPH_M = {"GLONASS": 2.8, "BeiDou": 1.4}


def _psd(kind: str, f: np.ndarray, rate: int) -> np.ndarray:
    tc = 1.0 / (CHIP_RATE_HZ * rate)
    if kind == "bpsk":
        return tc * np.sinc(f * tc) ** 2
    x = np.pi * f / CHIP_RATE_HZ  # BOC(1,1), sine phased
    with np.errstate(divide="ignore", invalid="ignore"):
        g = CHIP_RATE_HZ * (np.sin(x / 2) * np.sin(x) / (np.pi * f * np.cos(x / 2))) ** 2
    return np.where(np.abs(f) < 1e-9, 0.0, g)


@lru_cache(maxsize=None)
def _dll_integrals(signal: str) -> tuple[float, float, float, float]:
    """The four spectrum integrals of the DLL variance (10 ms each: kept in the cache directory)."""
    from tollcli.cache import cached_array

    name = f"dll-{'-'.join(map(str, SIGNALS[signal]))}-numpy{np.__version__}.npy"
    return tuple(float(v) for v in cached_array("sigma", name, lambda: _integrate(signal), shape=(4,)))


def _integrate(signal: str) -> tuple[float, float, float, float]:
    kind, bandwidth, spacing_chips, rate = SIGNALS[signal]
    f = np.linspace(-bandwidth / 2, bandwidth / 2, 200_001)
    df = f[1] - f[0]
    g = _psd(kind, f, rate)
    d = spacing_chips / (CHIP_RATE_HZ * rate)
    s, c = np.sin(np.pi * f * d), np.cos(np.pi * f * d)
    return (float(np.sum(g * s**2) * df), float(np.sum(f * g * s) * df), float(np.sum(g * c**2) * df), float(np.sum(g * c) * df))


def sigma_noise_dll_m(cn0_dbhz, signal: str = "bpsk1_wide", loop_bw_hz: float = 1.0, t_int_s: float = 0.02) -> np.ndarray:
    """Thermal-noise 1σ of a dot-product DLL (Betz & Kolodziejski), metres, for C/N0 in dB-Hz."""
    i_s2, i_fs, i_c2, i_c = _dll_integrals(signal)
    cn0 = 10.0 ** (np.asarray(cn0_dbhz, dtype=float) / 10.0)
    var_s2 = loop_bw_hz * (1 - 0.5 * loop_bw_hz * t_int_s) * i_s2 / ((2 * np.pi) ** 2 * cn0 * i_fs**2)
    squaring = 1.0 + i_c2 / (t_int_s * cn0 * i_c**2)
    return C_MPS * np.sqrt(var_s2 * squaring)


def obliquity(elev_deg) -> np.ndarray:
    """Ionospheric obliquity factor F = [1 − (R_e cosθ / (R_e + h_I))²]^(−1/2)."""
    cos_el = np.cos(np.radians(np.asarray(elev_deg, dtype=float)))
    return 1.0 / np.sqrt(1.0 - (EARTH_RADIUS_M * cos_el / (EARTH_RADIUS_M + IONO_HEIGHT_M)) ** 2)


def geomagnetic_lat_deg(lat_deg, lon_deg) -> np.ndarray:
    """sin φ_m = sin φ sin 78.3° + cos φ cos 78.3° cos(λ − 291°)."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    pole_lat, pole_lon = np.radians(78.3), np.radians(291.0)
    s = np.sin(lat) * np.sin(pole_lat) + np.cos(lat) * np.cos(pole_lat) * np.cos(lon - pole_lon)
    return np.degrees(np.arcsin(np.clip(s, -1.0, 1.0)))


def vertical_iono_m(geomag_lat_deg) -> np.ndarray:
    """τ_v: 9 m (|φ_m| ≤ 20°), 4.5 m (20°–55°), 6 m (> 55°)."""
    a = np.abs(np.asarray(geomag_lat_deg, dtype=float))
    return np.where(a <= 20.0, 9.0, np.where(a <= 55.0, 4.5, 6.0))


def sigma_iono_m(elev_deg, lat_deg, lon_deg, mode: str = "single") -> np.ndarray:
    """Ionospheric residual 1σ on L1/E1: ``single`` (F·τ_v), ``sbas`` (F·0.46 m), ``iono-free`` (0)."""
    f = obliquity(elev_deg)
    if mode == "single":
        return f * vertical_iono_m(geomagnetic_lat_deg(lat_deg, lon_deg))
    if mode == "sbas":
        return f * 0.46
    if mode == "iono-free":
        return np.zeros_like(f)
    raise ValueError(f"ionosphere mode {mode!r}: single, sbas or iono-free")


def sigma_tropo_m(elev_deg) -> np.ndarray:
    """DO-229 tropospheric residual 1σ; below 4° inflated by (1 + 0.015·(4° − θ)²)."""
    el = np.asarray(elev_deg, dtype=float)
    s = 0.12 * 1.001 / np.sqrt(0.002001 + np.sin(np.radians(el)) ** 2)
    return np.where(el < 4.0, s * (1.0 + 0.015 * (4.0 - el) ** 2), s)


@dataclass
class NominalModel:
    """The thesis's nominal model, with its choices as fields."""

    clk_eph_m: float = 0.85
    #: the clock & ephemeris σ (m) of the constellations whose broadcast orbits and clocks are worse than GPS's
    clk_eph_by_constellation: dict[str, float] = field(default_factory=lambda: dict(CLK_EPH_M))
    iono: str = "single"  # single | sbas | iono-free
    default_cn0_dbhz: float = 30.0
    signals: dict[str, str] = field(default_factory=lambda: dict(DEFAULT_SIGNALS))

    def sigma_m(self, elev_deg, cn0_dbhz, constellation, lat_deg, lon_deg) -> np.ndarray:
        """σ_PSR per measurement; arrays broadcast (``constellation`` an array of names, or a
        ``pandas.Categorical`` of them: its codes are used, no string is compared)."""
        elev = np.asarray(elev_deg, dtype=float)
        cn0 = np.asarray(cn0_dbhz, dtype=float)
        cn0 = np.where(np.isfinite(cn0) & (cn0 > 0), cn0, self.default_cn0_dbhz)
        if hasattr(constellation, "categories"):
            code, names = np.asarray(constellation.codes), [str(c) for c in constellation.categories]
            present = [names[k] for k in np.flatnonzero(np.bincount(code[code >= 0], minlength=len(names)))]
            const, of = code, {name: names.index(name) for name in present}
        else:
            const = np.asarray(constellation, dtype=object)
            present = set(const.ravel().tolist())  # a hash set: sorting 10^5 strings costs more
            of = {name: name for name in present}
        var = self.clk_eph_m**2 + sigma_iono_m(elev, lat_deg, lon_deg, self.iono) ** 2 + sigma_tropo_m(elev) ** 2
        shape = np.broadcast(elev, cn0, const).shape
        local = np.zeros(shape)
        cn0_b, const_b = np.broadcast_to(cn0, shape), np.broadcast_to(const, shape)
        for name in sorted(present):
            sel = const_b == of[name]
            signal = self.signals.get(str(name), "bpsk1_wide")
            c = cn0_b[sel]  # each constellation's measurements only (elementwise: the same values)
            local_var = sigma_noise_dll_m(c, signal) ** 2 + MULTIPATH_M[signal] ** 2
            if self.iono == "iono-free":  # second band BPSK(10) (L5/E5a) at the same C/N0
                local_var = KA2_L1L5 * local_var + KB2_L1L5 * (sigma_noise_dll_m(c, "bpsk10") ** 2 + MULTIPATH_M["bpsk10"] ** 2)
            clk = self.clk_eph_by_constellation.get(str(name))
            if clk is not None:  # its own clock & ephemeris σ in place of the common one
                local_var = local_var + (clk**2 - self.clk_eph_m**2)
            local[sel] = local_var
        return np.sqrt(var + local)


def sigma_for(model: str, *, elev_deg, cn0_dbhz, constellation, lat_deg, lon_deg,
              sigma_input_m=None, sigma_const_m: float = 5.0, nominal: NominalModel | None = None) -> np.ndarray:  # fmt: skip
    """σ per measurement under the named model (see module docstring)."""
    shape = np.shape(elev_deg)
    if model == "constant":
        return np.full(shape, float(sigma_const_m))
    if model == "input":
        if sigma_input_m is None:
            raise ValueError("sigma model 'input' needs a per-measurement uncertainty in the log (this format has none)")
        return np.asarray(sigma_input_m, dtype=float)
    if model in ("nominal", "urban", "rural"):
        return (nominal or NominalModel()).sigma_m(elev_deg, cn0_dbhz, constellation, lat_deg, lon_deg)
    raise ValueError(f"sigma model {model!r}: one of {', '.join(SIGMA_MODELS)}")


#: the real-error (urban) model: σ² = σ_nominal² + URBAN_FLOOR_M² + URBAN_CN0_M²·10^((URBAN_CN0_REF − C/N0)/URBAN_CN0_SLOPE_DB)
URBAN_FLOOR_M = 25.0
URBAN_CN0_M = 30.0
URBAN_CN0_REF_DBHZ = 35.0
URBAN_CN0_SLOPE_DB = 15.0
URBAN_DEFAULT_CN0_DBHZ = 30.0


def urban_sigma_m(sigma_nominal_m, cn0_dbhz=None) -> np.ndarray:
    """σ (m) of a pseudorange in a street canyon: the nominal σ plus a multipath/NLOS term from its C/N0.

    σ² = σ_nominal² + 25² + 30²·10^((35 − C/N0)/15) (C/N0 in dB-Hz; 30 where the log gives none): 27.3 m at
    50 dB-Hz, 39 m at 35, 52 m at 30, 72 m at 25, 102 m at 20 on top of a few metres nominal. The form is the
    C/N0 weighting real receivers use (σ² = a + b·10^(−C/N0/10), softened to 15 dB a decade); the constants are
    set so that, on the smartLoc Potsdamer Platz drive (u-blox, 20 038 pseudoranges with truth), K·σ_major of
    the all-in-view WLS bounds every horizontal error at K = 4.45 (P_MD 5e-5): the largest error is 4.1 σ_major
    (``benchmarks/integrity_truth.py`` measures it). NLOS signals, weaker, are weighted down by the same term.
    """
    cn0 = np.full(np.shape(sigma_nominal_m), np.nan) if cn0_dbhz is None else np.asarray(cn0_dbhz, dtype=float)
    cn0 = np.where(np.isfinite(cn0) & (cn0 > 0), cn0, URBAN_DEFAULT_CN0_DBHZ)
    excess = URBAN_FLOOR_M**2 + URBAN_CN0_M**2 * 10.0 ** ((URBAN_CN0_REF_DBHZ - cn0) / URBAN_CN0_SLOPE_DB)
    return np.sqrt(np.asarray(sigma_nominal_m, dtype=float) ** 2 + excess)
