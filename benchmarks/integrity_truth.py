"""Integrity against the truth on every real drive with a reference trajectory, and on the simulator's drives.

For each drive and setting: the epochs with a position, how many were declared valid (availability), how
many of those were further off than the bound they were declared against — MI (HPE > HPL) and HMI (HPE > HAL)
— and the largest such error; a Stanford diagram (HPE against HPL) per drive for the defaults. Drives:

* ``../shared/data/smartloc/Berlin_Potsdamer_Platz_*`` — a real u-blox drive through a deep urban canyon
  (libRSF; 1 372 epochs with truth);
* ``../shared/data/gsdc2021/Pixel4_derived.csv`` — GSDC 2021, Mountain View, 7 epochs with truth;
* ``../shared/data/gsdc2022/device_gnss.csv`` — GSDC 2022, 6 epochs standing still, with truth;
* ``samples/sim/*`` — the simulator's rural and urban drives, fault-free and with a fault (the papers' error
  model), with their truth.

Settings: the trajectory estimator of pseudorange logs (``--positioning smoothed`` and ``filtered``; ``auto``, the
default, smooths every log long enough to measure its noise) with the largest error over HPL among its valid epochs,
and two simulated city drives with odometry (10 000 epochs each, written once into ``integrity_truth/sim/``:
fault-free, and with a satellite fault and an outage) for it — Berlin and these two also without their odometry
(their ``odom3`` lines dropped into ``integrity_truth/sim/``: the GNSS-only motion model); on snapshot positions, the
RAIM modes (``ss`` the default, ``etc`` and ``classic`` the papers'), with and without FDE, under
``--environment auto`` (the default: σ widened as the residuals require) and ``open`` (the papers' nominal
model throughout); and the ``model`` level — HPL = K_H·σ_major of the geometry, no fault detection — under the
nominal σ and the urban σ. Also: the correlation time of the real errors (what ``--tc`` must exceed for
positions to count as independent evidence) and, on ``berlin_1_raw.csv``'s NLOS labels, how the urban σ weights
NLOS signals against line-of-sight ones.

Run from the repository root (≈ 5 min; the simulated city drives are written the first time):

    python benchmarks/integrity_truth.py            # prints the tables, writes benchmarks/integrity_truth/
    python benchmarks/integrity_truth.py --no-plots
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass

import numpy as np
import pandas as pd

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from tollcli.charging.truth_passages import truth_trajectory  # noqa: E402
from tollcli.gnss.pseudorange_inputs import pseudorange_epochs  # noqa: E402
from tollcli.gnss.sigma_models import NominalModel, urban_sigma_m  # noqa: E402
from tollcli.gnss.wls import wls_geometry  # noqa: E402
from tollcli.integrity.model_bound import model_hpl_m  # noqa: E402
from tollcli.integrity.raim import RaimParams  # noqa: E402
from tollcli.integrity.truth_check import errors_against_truth  # noqa: E402
from tollcli.job.log_integrity import iter_integrity  # noqa: E402

SHARED = os.path.join(ROOT, "..", "shared", "data")
OUT = os.path.join(ROOT, "benchmarks", "integrity_truth")
VALID = ("valid", "excluded_valid")


@dataclass
class Drive:
    name: str
    log: str
    kind: str
    truth: str
    sigma_model: str = "nominal"
    hals: tuple[float, ...] = (50.0, 30.0)
    positionings: tuple[str, ...] | None = None  # only the settings of these positionings (None: all)
    labels: tuple[str, ...] | None = None  # only the settings of these labels (None: all)


def drives() -> list[Drive]:
    out = []
    berlin = os.path.join(SHARED, "smartloc", "Berlin_Potsdamer_Platz_")
    if os.path.exists(berlin + "Input.txt"):
        out.append(Drive("Berlin Potsdamer Platz (u-blox)", berlin + "Input.txt", "librsf", berlin + "GT.txt"))
        out.append(Drive("Berlin Potsdamer Platz without odometry (u-blox, GNSS only)", without_odometry(berlin + "Input.txt", "berlin"),
                         "librsf", berlin + "GT.txt", labels=GNSS_ONLY_SETTINGS, positionings=("smoothed", "filtered", "snapshot")))  # fmt: skip
    pixel4 = os.path.join(SHARED, "gsdc2021")
    if os.path.exists(os.path.join(pixel4, "Pixel4_derived.csv")):
        for model in ("nominal", "input"):
            out.append(Drive(f"GSDC 2021 Pixel 4 (σ {model})", os.path.join(pixel4, "Pixel4_derived.csv"), "gsdc-derived",
                             os.path.join(pixel4, "Pixel4_ground_truth.csv"), model))  # fmt: skip
    g22 = os.path.join(SHARED, "gsdc2022")
    if os.path.exists(os.path.join(g22, "device_gnss.csv")):
        out.append(Drive("GSDC 2022 (standing)", os.path.join(g22, "device_gnss.csv"), "device-gnss",
                         os.path.join(g22, "ground_truth.csv")))  # fmt: skip
    out += city_drives() + city_drives(SENSOR_FAULT_SIMULATIONS) + town_drives()
    for drive in city_drives() + town_drives():
        name = drive.name.split(" (")[0]
        out.append(Drive(f"{name} without odometry (libRSF, GNSS only, 10 000 epochs)", without_odometry(drive.log, name.split()[-1]),
                         "librsf", drive.truth, labels=GNSS_ONLY_SETTINGS, positionings=("smoothed", "filtered", "snapshot")))  # fmt: skip
    for name in ("rural-clean", "urban-clean", "rural-fault", "urban-fault"):
        d = os.path.join(ROOT, "samples", "sim", name)
        out.append(Drive(f"simulated {name} (pseudoranges, one clock)", os.path.join(d, "drive-derived.csv"), "gsdc-derived",
                         os.path.join(d, "truth.csv"), hals=(50.0, 40.0, 30.0)))  # fmt: skip
        out.append(Drive(f"simulated {name} (NMEA GRS, a clock per constellation)", os.path.join(d, "drive.nmea"), "nmea",
                         os.path.join(d, "truth.csv"), hals=(50.0, 40.0, 30.0)))  # fmt: skip
    return out


#: simulated city drives with odometry (``tollcli simulate --nlos --odometry``, 2 000 s at 5 Hz): fault-free, and with
#: a 100 m fault on one satellite for 60 s and a 60 s outage (every satellite 40 dB down)
CITY_SIMULATIONS = (("city-clean", ("--seed", "11")),
                    ("city-fault", ("--seed", "12", "--fault-at", "600", "--fault-bias", "100", "--fault-duration", "60",
                                    "--jam-at", "1200", "--jam-duration", "60", "--jam-db", "40")))  # fmt: skip


#: the same with the vehicle's sensors wrong for a minute, twice: the odometer reading 10 % too much, the gyro's bias
#: 0.02 rad/s (1.1 °/s) off — not used to choose settings (``trajectory_settings.py``), only to show what they give
SENSOR_FAULT_SIMULATIONS = (("city-odometer", ("--seed", "13", "--sensor-fault-at", "600,1400", "--odometer-step", "0.1")),
                            ("city-gyro", ("--seed", "14", "--sensor-fault-at", "600,1400", "--gyro-step", "0.02")))  # fmt: skip


#: the settings a drive without its odometry is run with: the trajectory's and the snapshot RAIM's default
GNSS_ONLY_SETTINGS = ("smoothed trajectory", "filtered trajectory (forward only)", "ss (default)")


#: simulated town drives (``tollcli simulate --route helsinki.osm.pbf --tour``: shortest paths to random places of
#: Helsinki's streets, corners rounded to 10 m and taken at up to 2 m/s² sideways, a 20 s stop every 90 s, city
#: reflections, odometry; 2 000 s at 5 Hz): the drives whose motion is a town's — turns, braking, pulling away —
#: on which the GNSS-only motion model's white acceleration is chosen (``trajectory_settings.py``)
TOWN_SIMULATIONS = (("town-clean", ("--seed", "21")),
                    ("town-fault", ("--seed", "22", "--fault-at", "600", "--fault-bias", "100", "--fault-duration", "60",
                                    "--jam-at", "1200", "--jam-duration", "60", "--jam-db", "40")))  # fmt: skip
HELSINKI = os.path.join(SHARED, "osm", "helsinki.osm.pbf")


def town_drives(simulations=TOWN_SIMULATIONS) -> list[Drive]:
    """The simulated town drives, written once into ``benchmarks/integrity_truth/sim/`` (none without the map)."""
    import subprocess

    if not os.path.exists(HELSINKI):
        return []
    stops = ",".join(str(90 * k) for k in range(1, 23))
    out = []
    for name, extra in simulations:
        folder = os.path.join(OUT, "sim", name)
        if not os.path.exists(os.path.join(folder, "truth-librsf.txt")):
            subprocess.run([sys.executable, "-m", "tollcli", "simulate", "--route", HELSINKI, "--from", "60.1710,24.9440", "--tour", "25000",
                            "--turn-radius", "10", "--stop-at", stops, "--stop-duration", "20", "--nlos", "--odometry",
                            "--duration", "2000", "--rate", "5", *extra, "-o", folder, "-q"], check=True)  # fmt: skip
        out.append(Drive(f"simulated {name} (libRSF, odometry, 10 000 epochs, Helsinki streets)", os.path.join(folder, "drive-librsf.txt"),
                         "librsf", os.path.join(folder, "truth-librsf.txt"), positionings=("smoothed", "filtered")))  # fmt: skip
    return out


def without_odometry(log: str, name: str) -> str:
    """The libRSF log with its ``odom3`` lines dropped, written into ``integrity_truth/sim/`` (not kept in git)."""
    out = os.path.join(OUT, "sim", f"{name}-without-odometry.txt")
    if not os.path.exists(out):
        os.makedirs(os.path.dirname(out), exist_ok=True)
        with open(log) as src, open(out + ".part", "w") as dst:
            dst.writelines(line for line in src if not line.startswith("odom3"))
        os.replace(out + ".part", out)
    return out


def city_drives(simulations=CITY_SIMULATIONS) -> list[Drive]:
    """The simulated city drives, written once into ``benchmarks/integrity_truth/sim/`` (not kept in git)."""
    import subprocess

    out = []
    for name, extra in simulations:
        folder = os.path.join(OUT, "sim", name)
        if not os.path.exists(os.path.join(folder, "truth-librsf.txt")):
            subprocess.run([sys.executable, "-m", "tollcli", "simulate", "--nlos", "--odometry", "--duration", "2000", "--rate", "5",
                            *extra, "-o", folder, "-q"], check=True)  # fmt: skip
        out.append(Drive(f"simulated {name} (libRSF, odometry, 10 000 epochs)", os.path.join(folder, "drive-librsf.txt"), "librsf",
                         os.path.join(folder, "truth-librsf.txt"), positionings=("smoothed", "filtered")))  # fmt: skip
    return out


SETTINGS = [  # label, raim mode, fde, environment, positioning (a pseudorange log's; a navigation log's is its receiver's)
    ("smoothed trajectory", "ss", False, "auto", "smoothed"),
    ("filtered trajectory (forward only)", "ss", False, "auto", "filtered"),
    ("ss (default)", "ss", False, "auto", "snapshot"),
    ("ss + FDE", "ss", True, "auto", "snapshot"),
    ("ss, nominal σ", "ss", False, "open", "snapshot"),
    ("etc", "etc", False, "auto", "snapshot"),
    ("etc, nominal σ (before)", "etc", False, "open", "snapshot"),
    ("etc + FDE, nominal σ", "etc", True, "open", "snapshot"),
    ("classic, nominal σ", "classic", False, "open", "snapshot"),
    ("classic + FDE, nominal σ", "classic", True, "open", "snapshot"),
]


def counts(err: np.ndarray, valid: np.ndarray, hpl: np.ndarray, hal: float) -> dict:
    have = np.isfinite(err)
    v = valid & have
    with np.errstate(invalid="ignore"):
        return {"epochs": int(have.sum()), "valid": int(v.sum()), "availability_pct": 100.0 * v.sum() / max(have.sum(), 1),
                "MI": int(np.sum(v & (err > hpl))), "HMI": int(np.sum(v & (err > hal))),
                "max_hpe_valid_m": float(np.max(err[v])) if v.any() else float("nan")}  # fmt: skip


def smoothed_by_default(drive: Drive) -> bool:
    """``--positioning auto`` smooths the log (a pseudorange log long enough for a trajectory)."""
    if drive.kind == "nmea":
        return False
    from tollcli.integrity.trajectory import with_trajectory

    return with_trajectory(*measurements(drive), "auto")[2] == "smoothed"


def run_setting(drive: Drive, truth: pd.DataFrame, mode: str, fde: bool, environment: str, hal: float, positioning: str = "snapshot"):
    params = RaimParams(mode=mode, hal_m=hal, fde=fde)
    table = pd.concat([c.table for c in iter_integrity(drive.log, drive.kind, params, drive.sigma_model,
                                                          environment=environment, positioning=positioning)], ignore_index=True)  # fmt: skip
    vouched = table.assign(lat_deg=table["raim_lat_deg"], lon_deg=table["raim_lon_deg"])  # the position the RAIM vouches for
    err, _ = errors_against_truth(vouched, truth, tolerance_s=0.2)
    valid = table["raim_status"].astype(str).isin(VALID).to_numpy()
    return table, err, valid


def measurements(drive: Drive):
    """The drive's epochs and RAIM measurements (a whole log)."""
    if drive.kind != "nmea":
        return pseudorange_epochs(drive.log, drive.kind, None, drive.sigma_model, 5.0, NominalModel())
    from tollcli.gnss.nmea_measurements import AngleCarry, nmea_measurements
    from tollcli.readers.nmea import iter_nmea_tables

    chunks = list(iter_nmea_tables(drive.log, chunk_epochs=10**9))
    assert len(chunks) == 1
    return chunks[0].epochs, nmea_measurements(chunks[0].epochs, chunks[0].satellites, "nominal", 5.0, NominalModel(), AngleCarry())


def model_level(drive: Drive, truth: pd.DataFrame, hal: float) -> list[tuple[str, dict]]:
    from tollcli.geodesy import enu_shift2geodetic
    from tollcli.gnss.wls import post_fit_residuals

    epochs, meas = measurements(drive)
    rows = []
    for label, sigma in (("model level, nominal σ", meas.sigma_m), ("model level, urban σ", urban_sigma_m(meas.sigma_m, meas.cn0_dbhz))):
        sigma = np.where(meas.mask, sigma, np.nan)
        geometry = wls_geometry(meas.H, sigma, meas.mask)
        _, dx = post_fit_residuals(meas.H, geometry, meas.mask, meas.dy_m, meas.residual_m)  # the solution under these σ
        lat, lon = enu_shift2geodetic(epochs["lat_deg"].to_numpy(float), epochs["lon_deg"].to_numpy(float),
                                      np.nan_to_num(dx[:, 0]), np.nan_to_num(dx[:, 1]))  # fmt: skip
        err, _ = errors_against_truth(epochs.assign(lat_deg=lat, lon_deg=lon), truth, tolerance_s=0.2)
        hpl = model_hpl_m(geometry, sigma, 5e-5)
        rows.append((label, counts(err, hpl <= hal, hpl, hal)))
    return rows


def correlation_time_s(table: pd.DataFrame, truth: pd.DataFrame) -> float:
    """1/e time of the autocorrelation of the east and north errors (s), epochs resampled to 1 s."""
    from tollcli.geodesy import enu_rotation, geodetic2ecef
    from tollcli.times import nearest_index

    t = (table["time_utc"] - table["time_utc"].iloc[0]).dt.total_seconds().to_numpy()
    tt = (pd.to_datetime(truth["time_utc"], utc=True) - table["time_utc"].iloc[0]).dt.total_seconds().to_numpy()
    k, gap = nearest_index(tt, t)
    ok = (gap <= 0.2) & np.isfinite(table["lat_deg"].to_numpy(float))
    est = np.stack(geodetic2ecef(table["lat_deg"].to_numpy(float)[ok], table["lon_deg"].to_numpy(float)[ok], 0.0), -1)
    tru_lat, tru_lon = truth["lat_deg"].to_numpy(float)[k[ok]], truth["lon_deg"].to_numpy(float)[k[ok]]
    enu = np.einsum("eij,ej->ei", enu_rotation(tru_lat, tru_lon), est - np.stack(geodetic2ecef(tru_lat, tru_lon, 0.0), -1))
    grid = np.arange(0.0, t[ok].max(), 1.0)
    rho = []
    for axis in (0, 1):
        x = np.interp(grid, t[ok], enu[:, axis])
        x = x - x.mean()
        ac = np.correlate(x, x, "full")[x.size - 1:] / (np.arange(x.size, 0, -1) * x.var())
        rho.append(ac)
    ac = np.mean(rho, axis=0)
    below = np.flatnonzero(ac < np.exp(-1.0))
    return float(below[0]) if below.size else float("nan")


def nlos_weights() -> dict | None:
    """Median urban σ and C/N0 of the NLOS-labelled and line-of-sight signals of berlin_1_raw.csv."""
    path = os.path.join(SHARED, "smartloc", "berlin_1_raw.csv")
    if not os.path.exists(path):
        return None
    raw = pd.read_csv(path, sep=";")
    cn0 = pd.to_numeric(raw.filter(like="(cno)").iloc[:, 0], errors="coerce").to_numpy(float)
    nlos = pd.to_numeric(raw.filter(like="NLOS").iloc[:, 0], errors="coerce").to_numpy(float)
    sigma = urban_sigma_m(np.full(cn0.shape, 3.0), cn0)
    out = {}
    for label, sel in (("NLOS", nlos == 1), ("line of sight", nlos == 0)):
        out[label] = {"signals": int(sel.sum()), "median_cn0_dbhz": float(np.median(cn0[sel])),
                      "median_urban_sigma_m": float(np.median(sigma[sel])), "mean_weight": float(np.mean(sigma[sel] ** -2.0))}  # fmt: skip
    return out


def stanford(path: str, title: str, err: np.ndarray, hpl: np.ndarray, valid: np.ndarray, hal: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 4.6))
    top = float(np.nanmax(np.concatenate([err[np.isfinite(err)], hpl[np.isfinite(hpl)], [hal * 1.5]])))
    ax.plot([0, top], [0, top], color="black", lw=0.8)
    ax.axvline(hal, color="grey", ls="--", lw=0.8)
    ax.axhline(hal, color="grey", ls="--", lw=0.8)
    ok = np.isfinite(err) & np.isfinite(hpl)
    ax.scatter(hpl[ok & ~valid], err[ok & ~valid], s=5, color="#bbbbbb", label="not valid")
    ax.scatter(hpl[ok & valid], err[ok & valid], s=5, color="#1f77b4", label="valid")
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    ax.set_xlabel("HPL (m)")
    ax.set_ylabel("horizontal error against truth, HPE (m)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-plots", action="store_true")
    args = parser.parse_args(argv)
    os.makedirs(OUT, exist_ok=True)
    lines = ["# Integrity against the truth", "",
             "`python benchmarks/integrity_truth.py` — every real drive with a reference trajectory, and the simulator's drives.",
             "MI: declared valid with HPE > HPL; HMI: declared valid with HPE > HAL. Availability: valid / epochs with a position.",
             "HPE is measured at the position each setting vouches for: its own weighted solution, after any exclusion.", ""]  # fmt: skip
    for drive in drives():
        truth = truth_trajectory(drive.truth)
        lines += [f"## {drive.name}", "", "| setting | HAL m | valid / epochs | availability | MI | HMI | worst HPE while valid | largest HPE/HPL while valid |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
        extra_png: list[str] = []
        settings = [row for row in SETTINGS if (drive.kind != "nmea" or row[4] == "snapshot")
                    and (drive.positionings is None or row[4] in drive.positionings) and (drive.labels is None or row[0] in drive.labels)]  # fmt: skip
        default = "smoothed trajectory" if smoothed_by_default(drive) else "ss (default)"  # --positioning auto
        for hal in drive.hals:
            for label, mode, fde, environment, positioning in settings:
                table, err, valid = run_setting(drive, truth, mode, fde, environment, hal, positioning)
                hpl = table["hpl_m"].to_numpy(float)
                c = counts(err, valid, hpl, hal)
                with np.errstate(invalid="ignore", divide="ignore"):
                    margin = np.nanmax(np.where(valid, err / hpl, np.nan)) if valid.any() else float("nan")
                lines.append(f"| {label} | {hal:g} | {c['valid']} / {c['epochs']} | {c['availability_pct']:.1f} % | {c['MI']} | "
                             f"**{c['HMI']}** | {c['max_hpe_valid_m']:.1f} | {margin:.2f} |")  # fmt: skip
                if positioning != "snapshot" and hal == drive.hals[0] and not args.no_plots:
                    png = f"stanford-{drive.name.split(' (')[0].lower().replace(' ', '-')}-{positioning}.png"
                    stanford(os.path.join(OUT, png), f"{drive.name}: {positioning}, HAL {hal:g} m", err, hpl, valid, hal)
                    extra_png.append(f"![Stanford diagram, {positioning}]({png})")
                if label == "ss (default)" and hal == drive.hals[0] and not args.no_plots:
                    png = (f"stanford-{drive.name.split(' (')[0].lower().replace(' ', '-')}"
                           f"{'-' + drive.sigma_model if drive.sigma_model != 'nominal' else ''}{'-nmea' if drive.kind == 'nmea' else ''}.png")
                    stanford(os.path.join(OUT, png), f"{drive.name}: ss on snapshot positions, HAL {hal:g} m", err, hpl, valid, hal)
                    lines_png = f"![Stanford diagram]({png})"
                if label == "ss (default)" and hal == drive.hals[0]:
                    environments = table["environment"].astype(str).value_counts().to_dict()
                    f = table["variance_factor"].to_numpy(float)
                    env_line = (f"Snapshot RAIM: environment {environments}; variance factor over 30 s "
                                f"{np.nanmin(f):.2f}–{np.nanmax(f):.2f} (median {np.nanmedian(f):.2f}).") if np.isfinite(f).any() else ""
                    if len(table) > 100:
                        env_line += f" Error correlation time (1/e): {correlation_time_s(table, truth):.0f} s."
            for label, c in model_level(drive, truth, hal) if drive.positionings is None else ():
                lines.append(f"| {label} | {hal:g} | {c['valid']} / {c['epochs']} | {c['availability_pct']:.1f} % | {c['MI']} | "
                             f"**{c['HMI']}** | {c['max_hpe_valid_m']:.1f} | |")  # fmt: skip
        lines += ["", f"Default for this log: {default}. " + (env_line if drive.positionings is None else ""), ""]
        if not args.no_plots:
            lines += [*extra_png, *([lines_png] if drive.positionings is None else []), ""]
        print("\n".join(lines[-(len(drive.hals) * (len(settings) + 2) + 8):]), flush=True)
    nlos = nlos_weights()
    if nlos is not None:
        lines += ["## NLOS signals under the urban σ (smartLoc berlin_1_raw.csv labels)", "",
                  "| signals | count | median C/N0 dB-Hz | median urban σ m | mean weight 1/σ² |", "|---|---:|---:|---:|---:|"]  # fmt: skip
        for label, v in nlos.items():
            lines.append(f"| {label} | {v['signals']} | {v['median_cn0_dbhz']:.0f} | {v['median_urban_sigma_m']:.1f} | {v['mean_weight']:.2e} |")
        print("\n".join(lines[-4:]))
    with open(os.path.join(OUT, "integrity_truth.md"), "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"written {os.path.join(OUT, 'integrity_truth.md')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
