"""RAIM throughput on the GSDC Pixel 4 drive, next to gnss_lib_py's ``solve_fde`` (residual method).

* Same file: the 7-epoch derived CSV tiled ``--tiles`` times (each copy shifted
  by 10 s) is run end to end by both: ours = read + batched WLS + RAIM FDE;
  gnss_lib_py = ``AndroidDerived2021`` + ``solve_fde(method="residual")``.
* RAIM alone: the WLS measurement arrays tiled to ``--epochs`` epochs; FD
  (geometry + detection) and FDE, ETC with the safe look-up table and with the
  exact per-epoch quantile, and FDE with a 100 m fault in every epoch (so every
  epoch goes through exclusion: the worst case).
* Solution separation (the default RAIM) on the same arrays: the closed form (low-rank updates) beside the direct
  solve of every subset it replaced, in epoch·subsets per second on one core.

Needs ``pip install -e '.[bench]'`` for the gnss_lib_py baseline.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from tollcli.gnss.gsdc_positions import gsdc_epochs
from tollcli.gnss.measurements import Measurements
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim
from tollcli.readers.gsdc import read_gsdc_derived

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "gsdc2021" / "Pixel4_derived.csv"


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def tiled_csv(path: Path, tiles: int, out: Path) -> int:
    derived = pd.read_csv(path)
    copies = []
    for k in range(tiles):
        c = derived.copy()
        c["millisSinceGpsEpoch"] += k * 10_000
        copies.append(c)
    pd.concat(copies).to_csv(out, index=False)
    return derived["millisSinceGpsEpoch"].nunique() * tiles


def tile(meas: Measurements, reps: int) -> Measurements:
    return Measurements(
        np.tile(meas.H, (reps, 1, 1)), np.tile(meas.sigma_m, (reps, 1)), np.tile(meas.mask, (reps, 1)),
        np.tile(meas.sv, (reps, 1)), dy_m=np.tile(meas.dy_m, (reps, 1)),
        test_stat_source=np.tile(meas.test_stat_source, reps),
    )  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--tiles", type=int, default=100, help="copies of the 7-epoch file for the side-by-side run")
    parser.add_argument("--epochs", type=int, default=100_000, help="epochs for the RAIM-only runs")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "tiled_derived.csv"
        n_file = tiled_csv(args.data, args.tiles, csv)
        fde = RaimParams("etc", hal_m=50.0, p_md=5e-5, fde=True)
        fd = RaimParams("etc", hal_m=50.0, p_md=5e-5)
        table = read_gsdc_derived(csv)
        _, file_meas = gsdc_epochs(table, sigma_model="input")
        run_raim(file_meas, fd)  # warm the threshold table
        ours = {
            "read + WLS + FDE": best(lambda: run_raim(gsdc_epochs(read_gsdc_derived(csv), sigma_model="input")[1], fde), args.repeat),
            "WLS + FDE": best(lambda: run_raim(gsdc_epochs(table, sigma_model="input")[1], fde), args.repeat),
            "FD (given the WLS solution)": best(lambda: run_raim(file_meas, fd), args.repeat),
        }
        print(f"same file: {n_file} epochs ({args.tiles} copies of the GSDC Pixel 4 drive, {len(table)} measurements)")
        for label, t in ours.items():
            print(f"  tollcli {label:32s} {n_file / t:12,.0f} epochs/s")
        try:
            import gnss_lib_py as glp
            from gnss_lib_py.algorithms.fde import solve_fde
        except ImportError:
            print("  gnss_lib_py not installed: pip install -e '.[bench]' for the baseline")
        else:
            start = time.perf_counter()
            navdata = glp.AndroidDerived2021(str(csv), remove_timing_outliers=False)
            t_load = time.perf_counter() - start
            start = time.perf_counter()
            solve_fde(navdata, method="residual", remove_outliers=False)
            t_fde = time.perf_counter() - start
            print(f"  gnss_lib_py read (AndroidDerived2021) + solve_fde   {n_file / (t_load + t_fde):12,.0f} epochs/s")
            print(f"  gnss_lib_py solve_fde(residual) alone               {n_file / t_fde:12,.0f} epochs/s")
            print(f"  ratio, read + WLS + FDE:  {(t_load + t_fde) / ours['read + WLS + FDE']:8,.0f}x")
            print(f"  ratio, WLS + FDE vs solve_fde: {t_fde / ours['WLS + FDE']:8,.0f}x")
            print(f"  ratio, FD vs solve_fde:   {t_fde / ours['FD (given the WLS solution)']:8,.0f}x")

    _, meas = gsdc_epochs(read_gsdc_derived(args.data), sigma_model="input")
    reps = max(1, args.epochs // meas.mask.shape[0])
    big = tile(meas, reps)
    n = big.mask.shape[0]
    print(f"RAIM only, {n} epochs of {int(meas.mask.sum(1).mean())} measurements (GSDC arrays tiled):")
    cases = [
        ("FD  ETC (safe look-up table)", RaimParams("etc", 50.0, 5e-5), big),
        ("FD  ETC (exact ncx2 quantile)", RaimParams("etc", 50.0, 5e-5, exact_threshold=True), big),
        ("FD  classic", RaimParams("classic", 50.0, 5e-5, 5e-3), big),
        ("FDE ETC, data as is", RaimParams("etc", 50.0, 5e-5, fde=True), big),
    ]
    faulty = tile(meas, reps)
    faulty.dy_m = faulty.dy_m.copy()
    faulty.dy_m[:, 1] += 1000.0  # E13 E1, σ 1.8 m: a fault the RAIM must detect
    cases.append(("FDE ETC, 1 km fault every epoch", RaimParams("etc", 50.0, 5e-5, fde=True), faulty))
    for label, params, m in cases:
        run_raim(m, params)  # warm the threshold table
        t = best(lambda: run_raim(m, params), args.repeat)
        print(f"  {label:34s} {n / t:12,.0f} epochs/s")
    separation(big, args.repeat)


def separation(meas: Measurements, repeat: int) -> None:
    """Solution separation (the default RAIM) on the same arrays: the closed form against the direct solve of every
    subset it replaced, in epoch·subsets per second (a subset: a satellite or a constellation left out)."""
    from tollcli.gnss.wls import post_fit_residuals, wls_geometry
    from tollcli.integrity.solution_separation import clock_columns, solution_separation

    geometry = wls_geometry(meas.H, meas.sigma_m, meas.mask)
    r, _ = post_fit_residuals(meas.H, geometry, meas.mask, meas.dy_m, None)
    clocks = clock_columns(meas.H, meas.mask)
    subsets = int((meas.mask.sum(axis=1) + clocks.max(axis=1) + 1).sum())
    print(f"solution separation, {meas.mask.shape[0]} epochs, {subsets} epoch·subsets (one core):")
    times = {}
    for label, closed in (("closed form (low-rank updates)", True), ("direct solve of every subset (before)", False)):
        times[closed] = best(lambda: solution_separation(meas.H, meas.sigma_m, meas.mask, np.nan_to_num(r), clocks, geometry,
                                                         5e-5, 5e-3, closed_form=closed), repeat)  # fmt: skip
        print(f"  {label:40s} {subsets / times[closed]:12,.0f} epoch·subsets/s")
    print(f"  ratio, closed form / direct: {times[False] / times[True]:.1f}x faster")


if __name__ == "__main__":
    main()
