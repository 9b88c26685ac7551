"""PNG figures of a run (matplotlib, no screen needed).

* ``trajectory.png``: geo-objects (charged ones filled) and the positions coloured by RAIM status;
* ``protection.png``: HPL (or HAL, ETC RAIM) and P_FA over time, statuses along the bottom;
* ``valid_positions.png``: valid independent positions per geo-object passage against N_Th;
* ``stanford.png`` (with a truth trajectory): horizontal error against HPL, the regions counted.
"""

from __future__ import annotations

import os

import numpy as np

from tollcli.io.writers import output_folder
from tollcli.report.run_data import RunData

STATUS_COLOURS = {
    "valid": "#1a9850", "excluded_valid": "#91cf60", "fault_detected": "#d73027", "unavailable": "#fc8d59",
    "unmonitored": "#999999", "insufficient": "#555555",
}  # fmt: skip


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_plots(run: RunData, outdir: str) -> list[str]:
    """Write the figures into ``outdir``; returns their paths."""
    output_folder(outdir, "figures")
    paths = [_trajectory(run, outdir), _protection(run, outdir), _valid_positions(run, outdir)]
    if run.truth is not None and "horiz_error_m" in run.epochs:
        paths.append(_stanford(run, outdir))
    return paths


def _save(fig, outdir: str, name: str) -> str:
    path = os.path.join(outdir, name)
    tmp = path + ".tmp.png"
    fig.savefig(tmp, dpi=110, metadata={"Software": None})
    os.replace(tmp, path)
    _plt().close(fig)
    return path


def _trajectory(run: RunData, outdir: str) -> str:
    import shapely

    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 7))
    charged = {line["geoobject"] for line in run.invoice["lines"]}
    for feature in run.geo_features:
        geom = shapely.geometry.shape(feature["geometry"])
        gid = str(feature["properties"].get("id"))
        for poly in getattr(geom, "geoms", [geom]):
            x, y = poly.exterior.xy
            ax.fill(x, y, color="#4575b4" if gid in charged else "#bbbbbb", alpha=0.25, lw=0)
            ax.plot(x, y, color="#4575b4" if gid in charged else "#888888", lw=1)
        c = geom.representative_point()
        ax.annotate(gid, (c.x, c.y), fontsize=8, ha="center")
    e = run.epochs
    lon = e["raim_lon_deg"] if "raim_lon_deg" in e else e["lon_deg"]
    lat = e["raim_lat_deg"] if "raim_lat_deg" in e else e["lat_deg"]
    for status, colour in STATUS_COLOURS.items():
        sel = e["raim_status"].astype(str) == status
        if sel.any():
            ax.scatter(lon[sel], lat[sel], s=6, color=colour, label=f"{status} ({int(sel.sum())})", zorder=3)
    if run.truth is not None:
        ax.plot(run.truth["lon_deg"], run.truth["lat_deg"], color="black", lw=0.8, label="truth", zorder=2)
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_aspect(1 / np.cos(np.radians(np.nanmean(lat))) if np.isfinite(np.nanmean(lat)) else 1.0)
    ax.set_title(f"{run.invoice.get('vehicle', '')}: positions by RAIM status, geo-objects (charged: blue)")
    ax.legend(fontsize=8, loc="best")
    return _save(fig, outdir, "trajectory.png")


def _protection(run: RunData, outdir: str) -> str:
    plt = _plt()
    e = run.epochs
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax1.plot(e["t_s"], e["hpl_m"], lw=1, label="HPL (m)")
    ax1.plot(e["t_s"], e["hal_m"], lw=1, ls="--", color="black", label="HAL (m)")
    ax1.set_ylabel("metres")
    ax1.legend(fontsize=8)
    ax1.set_title(f"RAIM {e['raim_mode'].iloc[0]}: protection level and false-alarm probability")
    ax2.semilogy(e["t_s"], e["p_fa"].clip(lower=1e-12), lw=1, color="C1", label="P_FA")
    ymin = 1e-12
    for status, colour in STATUS_COLOURS.items():
        sel = (e["raim_status"].astype(str) == status).to_numpy()
        if sel.any():
            ax2.scatter(e["t_s"][sel], np.full(sel.sum(), ymin * 3), s=4, color=colour, label=status)
    ax2.set_ylabel("P_FA")
    ax2.set_xlabel("time from the first epoch (s)")
    ax2.legend(fontsize=7, ncol=3)
    return _save(fig, outdir, "protection.png")


def _valid_positions(run: RunData, outdir: str) -> str:
    plt = _plt()
    items = [(ln["geoobject"], ln["entry_utc"][11:19], ln["n_valid_independent"], True) for ln in run.invoice["lines"]]
    items += [(ln["geoobject"], ln["entry_utc"][11:19], ln["n_valid_independent"], False) for ln in run.invoice.get("not_charged", [])]
    items.sort(key=lambda i: i[1])
    n_th = int((run.invoice.get("parameters") or {}).get("n_th", 1))
    fig, ax = plt.subplots(figsize=(max(5, 0.6 * len(items) + 2), 4))
    if items:
        ax.bar(range(len(items)), [i[2] for i in items], color=["#1a9850" if i[3] else "#d73027" for i in items])
        ax.set_xticks(range(len(items)), [f"{i[0]}\n{i[1]}" for i in items], fontsize=7)
    ax.axhline(n_th, color="black", ls="--", lw=1, label=f"N_Th = {n_th}")
    ax.set_ylabel("valid independent positions")
    ax.set_title("Per geo-object passage (green: charged, red: seen, not charged)")
    ax.legend()
    fig.tight_layout()
    return _save(fig, outdir, "valid_positions.png")


def _stanford(run: RunData, outdir: str) -> str:
    plt = _plt()
    e = run.epochs
    err, hpl, hal = e["horiz_error_m"].to_numpy(float), e["hpl_m"].to_numpy(float), float(run.hal_m)
    xlabel = "HPL (m)"
    if str(e["raim_mode"].iloc[0]) == "etc":  # HPL ≡ HAL there: plot the classic HPL of the same geometry instead
        from tollcli.integrity.design import classic_lambda_det

        params = run.invoice.get("parameters") or {}
        p_fa, p_md = float(params.get("p_fa", 5e-3)), float(params.get("p_md", 5e-5))
        dof = e["dof"].to_numpy(float)
        lam = np.where(dof >= 1, classic_lambda_det(p_fa, p_md, np.maximum(dof, 1).astype(int)), np.nan)
        hpl = e["slope_max_m"].to_numpy(float) * np.sqrt(lam)
        xlabel = f"classic HPL at P_FA {p_fa:g}, P_MD {p_md:g} (m) — the ETC RAIM's HPL is HAL"
    fig, ax = plt.subplots(figsize=(6.5, 6))
    ok = np.isfinite(err) & np.isfinite(hpl)
    valid = e["raim_status"].astype(str).isin(["valid", "excluded_valid"]).to_numpy()
    ax.scatter(hpl[ok & valid], err[ok & valid], s=5, color="#1a9850", label="valid")
    ax.scatter(hpl[ok & ~valid], err[ok & ~valid], s=5, color="#d73027", label="not valid")
    top = max(np.nanmax(err[ok], initial=hal), np.nanmax(hpl[ok], initial=hal), hal) * 1.1
    ax.plot([0, top], [0, top], color="black", lw=0.8)
    ax.axvline(hal, color="grey", ls="--", lw=0.8)
    ax.axhline(hal, color="grey", ls="--", lw=0.8)
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    r = run.truth_check["regions"] if run.truth_check else {}
    ax.set_title("Stanford diagram: " + ", ".join(f"{k} {v}" for k, v in r.items()), fontsize=8)
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel("horizontal error (m)")
    ax.legend(fontsize=8)
    return _save(fig, outdir, "stanford.png")
