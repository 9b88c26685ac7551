"""Figures of a run (matplotlib, no screen needed): PNG, or SVG or PDF (``fmt``).

* ``trajectory.png``: geo-objects (charged ones filled) and the positions coloured by RAIM status;
* ``protection.png``: HPL and HAL and P_FA over time, statuses along the bottom (ETC RAIM, whose HPL is HAL:
  the classic HPL of the same geometry, what the position could be bounded by);
* ``valid_positions.png``: valid independent positions per geo-object passage against N_Th;
* ``stanford.png`` (with a truth trajectory): horizontal error against HPL, the regions counted.

A panel with nothing to draw says so ("nothing to show: …") rather than staying blank. The trajectory is
framed on the positions (the geo-objects they pass, not the whole network: a log far from every
geo-object is not squashed into a strip), and says how many geo-objects lie outside the frame.
"""

from __future__ import annotations

import os

import numpy as np

from tollcli.io.writers import output_folder
from tollcli.report.run_data import RunData

STATUS_COLOURS = {
    "valid": "#1a9850", "excluded_valid": "#91cf60", "fault_detected": "#d73027", "probable_false_alarm": "#f4a6c0", "unavailable": "#fc8d59",
    "unmonitored": "#999999", "insufficient": "#555555",
}  # fmt: skip


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


PLOT_FORMATS = ("png", "svg", "pdf")


def write_plots(run: RunData, outdir: str, fmt: str = "png") -> list[str]:
    """Write the figures into ``outdir`` as ``fmt`` (png, svg or pdf); returns their paths."""
    output_folder(outdir, "figures")
    paths = [_trajectory(run, outdir, fmt), _protection(run, outdir, fmt), _valid_positions(run, outdir, fmt)]
    if run.truth is not None and "horiz_error_m" in run.epochs:
        paths.append(_stanford(run, outdir, fmt))
    return paths


#: metadata that would carry the time or the library's version: left out, so the same run gives the same bytes
_NO_STAMP = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None},
             "pdf": {"Creator": None, "Producer": None, "CreationDate": None}}


def _save(fig, outdir: str, name: str, fmt: str = "png") -> str:
    path = os.path.join(outdir, f"{name}.{fmt}")
    tmp = f"{path}.tmp.{fmt}"
    fig.savefig(tmp, format=fmt, dpi=110, metadata=_NO_STAMP[fmt])
    os.replace(tmp, path)
    _plt().close(fig)
    return path


def _nothing(ax, why: str) -> None:
    """Say on an empty panel that there is nothing to show, and why."""
    ax.text(0.5, 0.5, f"nothing to show: {why}", ha="center", va="center", transform=ax.transAxes, color="#555555",
            fontsize=10, wrap=True)  # fmt: skip


def _frame(lon: np.ndarray, lat: np.ndarray, pad: float = 0.08, min_span_deg: float = 0.005) -> tuple[float, float, float, float]:
    """(west, east, south, north) around the finite points, padded, never narrower than ``min_span_deg``."""
    ok = np.isfinite(lon) & np.isfinite(lat)
    w, e, s, n = lon[ok].min(), lon[ok].max(), lat[ok].min(), lat[ok].max()
    cx, cy = (w + e) / 2, (s + n) / 2
    hx, hy = max(e - w, min_span_deg) * (0.5 + pad), max(n - s, min_span_deg) * (0.5 + pad)
    return cx - hx, cx + hx, cy - hy, cy + hy


def _trajectory(run: RunData, outdir: str, fmt: str = "png") -> str:
    import shapely

    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 7))
    charged = {line["geoobject"] for line in run.invoice["lines"]}
    e = run.epochs
    lon = (e["raim_lon_deg"] if "raim_lon_deg" in e else e["lon_deg"]).to_numpy(float)
    lat = (e["raim_lat_deg"] if "raim_lat_deg" in e else e["lat_deg"]).to_numpy(float)
    have = np.isfinite(lon) & np.isfinite(lat)
    shapes = [(str(f["properties"].get("id")), shapely.geometry.shape(f["geometry"])) for f in run.geo_features]
    if have.any():  # frame the drive (and what it was charged for), not the whole network
        west, east, south, north = _frame(np.r_[lon[have], *[np.asarray(g.bounds)[[0, 2]] for i, g in shapes if i in charged]],
                                          np.r_[lat[have], *[np.asarray(g.bounds)[[1, 3]] for i, g in shapes if i in charged]])  # fmt: skip
    elif shapes:
        bounds = np.array([g.bounds for _, g in shapes])
        west, east, south, north = _frame(bounds[:, [0, 2]].ravel(), bounds[:, [1, 3]].ravel())
    else:
        west, east, south, north = -1.0, 1.0, -1.0, 1.0
    view = shapely.box(west, south, east, north)
    outside = 0
    for gid, geom in shapes:
        if not geom.intersects(view):
            outside += 1
            continue
        for poly in getattr(geom, "geoms", [geom]):
            x, y = poly.exterior.xy
            ax.fill(x, y, color="#4575b4" if gid in charged else "#bbbbbb", alpha=0.25, lw=0)
            ax.plot(x, y, color="#4575b4" if gid in charged else "#888888", lw=1)
        c = geom.intersection(view).representative_point()
        ax.annotate(gid, (c.x, c.y), fontsize=8, ha="center")
    status = e["raim_status"].astype(str).to_numpy()
    for name, colour in STATUS_COLOURS.items():
        sel = (status == name) & have
        if sel.any():
            ax.scatter(lon[sel], lat[sel], s=6, color=colour, label=f"{name} ({int(sel.sum())})", zorder=3)
    if run.truth is not None:
        ax.plot(run.truth["lon_deg"], run.truth["lat_deg"], color="black", lw=0.8, label="truth", zorder=2)
    ax.set_xlim(west, east)
    ax.set_ylim(south, north)
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.ticklabel_format(useOffset=False, style="plain")  # degrees as they are, never "-0.070 + -1.22e2"
    mid = (south + north) / 2
    ax.set_aspect(1 / max(np.cos(np.radians(mid)), 0.05))
    ax.set_title(f"{run.invoice.get('vehicle', '')}: positions by RAIM status, geo-objects (charged: blue)", fontsize=10, wrap=True)
    if not have.any():
        _nothing(ax, "the log has no position")
    if outside:
        ax.text(0.01, 0.01, f"{outside} of {len(shapes)} geo-objects lie outside this view", transform=ax.transAxes,
                fontsize=8, color="#555555")  # fmt: skip
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _save(fig, outdir, "trajectory", fmt)


def _protection(run: RunData, outdir: str, fmt: str = "png") -> str:
    plt = _plt()
    e = run.epochs
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    mode = str(e["raim_mode"].iloc[0]) if len(e) else ""
    ax1.set_title(f"RAIM {mode}: protection level and false-alarm probability", fontsize=10)
    ax1.set_ylabel("metres")
    ax2.set_ylabel("P_FA")
    ax2.set_xlabel("time from the first epoch (s)")
    if not np.isfinite(e["hpl_m"].to_numpy(float)).any():
        _nothing(ax1, "no epoch has a protection level (too few satellites, or no satellite reported)")
    else:
        if mode == "etc":  # HPL ≡ HAL: a flat line on the HAL; what the geometry could bound instead
            hpl, label = classic_hpl(run)
            ax1.plot(e["t_s"], hpl, lw=1, label=label)
            ax1.set_title("RAIM etc (HPL = HAL): the classic HPL of the same geometry, and the false-alarm probability", fontsize=10)
        else:
            ax1.plot(e["t_s"], e["hpl_m"], lw=1, label="HPL (m)")
        ax1.plot(e["t_s"], e["hal_m"], lw=1, ls="--", color="black", label="HAL (m)")
        ax1.legend(fontsize=8)
    p_fa = e["p_fa"].to_numpy(float)
    if not np.isfinite(p_fa).any():
        _nothing(ax2, "no epoch has a false-alarm probability")
        ax2.set_yscale("log")
    else:
        ax2.semilogy(e["t_s"], np.clip(p_fa, 1e-12, None), lw=1, color="C1", label="P_FA")
        p_fa_asked = (run.invoice.get("parameters") or {}).get("p_fa")
        if isinstance(p_fa_asked, (int, float)) and mode == "etc":
            ax2.axhline(p_fa_asked, color="#d73027", ls=":", lw=1, label=f"p_fa {p_fa_asked:g}: an alarm above is probably false")
    ymin = 1e-12
    status = e["raim_status"].astype(str).to_numpy()
    for name, colour in STATUS_COLOURS.items():
        sel = status == name
        if sel.any():
            ax2.scatter(e["t_s"][sel], np.full(sel.sum(), ymin * 3), s=4, color=colour, label=name)
    if ax2.get_legend_handles_labels()[0]:
        ax2.legend(fontsize=7, ncol=3)
    if (status == "probable_false_alarm").any():
        fig.text(0.01, 0.005, "probable_false_alarm: t > Th at a P_FA above p_fa — ETC keeps HPL = HAL by lowering Th, and "
                 "pays in false alarms. Not trusted, not charged on; no evidence of a fault.", fontsize=7, color="#555555")  # fmt: skip
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return _save(fig, outdir, "protection", fmt)


def _valid_positions(run: RunData, outdir: str, fmt: str = "png") -> str:
    plt = _plt()
    items = [(ln["geoobject"], ln["entry_utc"][11:19], ln["n_valid_independent"], True) for ln in run.invoice["lines"]]
    items += [(ln["geoobject"], ln["entry_utc"][11:19], ln["n_valid_independent"], False) for ln in run.invoice.get("not_charged", [])]
    items.sort(key=lambda i: i[1])
    n_th = int((run.invoice.get("parameters") or {}).get("n_th", 1))
    fig, ax = plt.subplots(figsize=(max(7, 0.6 * len(items) + 2), 4))
    if items:
        ax.bar(range(len(items)), [i[2] for i in items], color=["#1a9850" if i[3] else "#d73027" for i in items])
        ax.set_xticks(range(len(items)), [f"{i[0]}\n{i[1]}" for i in items], fontsize=7)
    else:
        _nothing(ax, "no geo-object passage in this log")
    ax.axhline(n_th, color="black", ls="--", lw=1, label=f"N_Th = {n_th}")
    ax.set_ylabel("valid independent positions")
    ax.set_title("Valid independent positions per passage\n(green: charged, red: seen, not charged)", fontsize=10)
    ax.legend()
    fig.tight_layout()
    return _save(fig, outdir, "valid_positions", fmt)


def _stanford(run: RunData, outdir: str, fmt: str = "png") -> str:
    return _save(stanford_figure(run), outdir, "stanford", fmt)


def classic_hpl(run: RunData) -> tuple[np.ndarray, str]:
    """The classic RAIM's HPL of each epoch's geometry (m) and its label: what an ETC run (HPL ≡ HAL) is drawn with."""
    from tollcli.integrity.design import classic_lambda_det

    e = run.epochs
    params = run.invoice.get("parameters") or {}
    p_fa, p_md = float(params.get("p_fa", 5e-3)), float(params.get("p_md", 5e-5))
    dof = e["dof"].to_numpy(float) if "dof" in e else np.full(len(e), np.nan)
    slope = e["slope_max_m"].to_numpy(float) if "slope_max_m" in e else np.full(len(e), np.nan)
    ok = np.isfinite(dof) & (dof >= 1)
    lam = np.full(len(e), np.nan)
    if ok.any():
        lam[ok] = classic_lambda_det(p_fa, p_md, dof[ok].astype(int))
    return slope * np.sqrt(lam), f"classic HPL at P_FA {p_fa:g}, P_MD {p_md:g} (m) — the ETC RAIM's HPL is HAL"


def stanford_figure(run: RunData):
    """The Stanford diagram of a run with a truth (horizontal error against HPL), as a matplotlib figure."""
    plt = _plt()
    e = run.epochs
    err, hpl, hal = e["horiz_error_m"].to_numpy(float), e["hpl_m"].to_numpy(float), float(run.hal_m)
    xlabel = "HPL (m)"
    if str(e["raim_mode"].iloc[0]) == "etc":  # HPL ≡ HAL there: plot the classic HPL of the same geometry instead
        hpl, xlabel = classic_hpl(run)
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
    if ok.any():
        ax.legend(fontsize=8)
    else:
        _nothing(ax, "no epoch has both a position error (the truth at its time) and a protection level")
    fig.tight_layout()
    return fig


def figure_png(fig) -> bytes:
    """A figure as PNG bytes (no time stamp: the same figure gives the same bytes)."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, metadata={"Software": None})
    _plt().close(fig)
    return buf.getvalue()
