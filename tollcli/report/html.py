"""One self-contained HTML page for auditing a trip: map, invoice, findings and the per-epoch table.

Leaflet (BSD-2, vendored in ``static/``) and every datum are inlined: the page opens
offline and fetches nothing. There is no background map unless ``tiles`` (a URL
template such as an operator's own tile server) is given — then the page is no
longer offline, by the user's choice.
"""

from __future__ import annotations

import base64
import html
import json
from importlib import resources

import numpy as np
import pandas as pd

from tollcli.integrity.raim import STATUS_MEANINGS
from tollcli.report.plots import STATUS_COLOURS, figure_png, stanford_figure
from tollcli.report.run_data import RunData

EPOCH_COLUMNS = ("time_utc", "raim_lat_deg", "raim_lon_deg", "raim_status", "hpl_m", "hal_m", "p_fa", "test_stat",
                 "threshold", "n_used", "excluded_sv", "geoobject")  # fmt: skip


def _static(name: str) -> str:
    return resources.files("tollcli.report").joinpath("static", name).read_text(encoding="utf-8")


def _json_for_script(doc) -> str:
    """JSON safe inside a <script> element."""
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def _num(v, fmt: str) -> str:
    return "" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, fmt)


def _table(headers: list[str], rows: list[list[str]], css: str = "") -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f'<table class="{css}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def report_html(run: RunData, tiles: str | None = None) -> str:
    inv = run.invoice
    e = run.epochs
    charged = sorted({line["geoobject"] for line in inv["lines"]})
    lat = e["raim_lat_deg"].to_numpy(float)
    lon = e["raim_lon_deg"].to_numpy(float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    status = e["raim_status"].astype(str).to_numpy()
    points = [[round(float(a), 7), round(float(b), 7), s] for a, b, s in zip(lat[ok], lon[ok], status[ok])]
    data = {
        "geoobjects": {"type": "FeatureCollection", "features": run.geo_features},
        "charged": charged, "points": points, "colours": STATUS_COLOURS, "tiles": tiles,
        "truth": [[round(float(a), 7), round(float(b), 7)] for a, b in zip(run.truth["lat_deg"], run.truth["lon_deg"])] if run.truth is not None else None,
    }  # fmt: skip
    per_km = any("tariff_table" in ln for ln in inv["lines"])  # per-km tables: the table, length and rate charged
    more = lambda ln: [ln.get("tariff_table", ""), ln.get("length_km") or "", ln.get("rate_per_km", "")] if per_km else []  # noqa: E731
    lines = [[ln["geoobject"], ln.get("name", ""), ln["entry_utc"], ln["exit_utc"], ln["n_valid_independent"], ln.get("band", ""), *more(ln), ln["fee"]]
             for ln in inv["lines"]]  # fmt: skip
    lines.append(["TOTAL", "", "", "", "", *([""] * (3 if per_km else 0)), inv["currency"], inv["total"]])
    invoice_columns = ["geo-object", "name", "entry (UTC)", "exit (UTC)", "valid independent", "band",
                       *(["table", "km", "rate per km"] if per_km else []), "fee"]  # fmt: skip
    missed = [[ln["geoobject"], ln["entry_utc"], ln["n_inside"], ln["n_valid"], ", ".join(f"{k} {v}" for k, v in ln.get("statuses", {}).items())]
              for ln in inv.get("not_charged", [])]  # fmt: skip
    findings = [[f["kind"], f["category"], f["start_utc"], f["end_utc"], json.dumps(f["evidence"], sort_keys=True)]
                for f in (inv.get("findings") or {}).get("items", [])]  # fmt: skip
    counts = pd.Series(status).value_counts().sort_index()
    epoch_rows = []
    for row in e[[c for c in EPOCH_COLUMNS if c in e]].itertuples(index=False):
        epoch_rows.append([
            pd.Timestamp(row.time_utc).strftime("%H:%M:%S.%f")[:-3] if pd.notna(row.time_utc) else "",
            _num(row.raim_lat_deg, ".7f"), _num(row.raim_lon_deg, ".7f"), row.raim_status, _num(row.hpl_m, ".1f"),
            _num(row.hal_m, ".1f"), _num(row.p_fa, ".2e"), _num(row.test_stat, ".2f"), _num(row.threshold, ".2f"),
            row.n_used, row.excluded_sv or "", row.geoobject,
        ])  # fmt: skip
    truth = ""
    if run.truth_check:
        c = run.truth_check
        truth = (f"<h2>Against the truth</h2><p>{c['with_position']} positions; horizontal error median "
                 f"{_num(c['horizontal_error_m']['median'], '.1f')} m, 95 % {_num(c['horizontal_error_m']['p95'], '.1f')} m; "
                 f"{c['positioning_failures']} positioning failures, {c['undetected']} undetected. Regions: "
                 + html.escape(", ".join(f"{k} {v}" for k, v in c["regions"].items())) + "</p>")  # fmt: skip
    if run.truth is not None and "horiz_error_m" in e:
        png = base64.b64encode(figure_png(stanford_figure(run))).decode("ascii")
        truth += f'<p><img alt="Stanford diagram: horizontal error against HPL" src="data:image/png;base64,{png}"></p>'
    p_fa_asked = inv["parameters"].get("p_fa")
    meanings = "".join(f'<li><b style="color:{STATUS_COLOURS.get(k, "#000")}">{html.escape(k)}</b> ({v}): '
                       f"{html.escape(STATUS_MEANINGS[k])}</li>" for k, v in counts.items() if k in STATUS_MEANINGS)  # fmt: skip
    if "probable_false_alarm" in counts:
        meanings += (f"<li>The line between a credible alarm and a probable false one is p_fa = {html.escape(str(p_fa_asked))} "
                     "(<code>--p-fa</code>). The ETC RAIM fixes the protection level at the HAL and lets P_FA vary per epoch: "
                     "with weak geometry it alarms often without any fault. Charging needs only N_Th independent valid "
                     "positions per passage, so false alarms cost evidence, not money wrongly charged.</li>")  # fmt: skip
    title = f"tollcli audit report — {inv.get('vehicle', '')}"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>{_static("leaflet.css")}</style>
<style>
body {{ font-family: system-ui, sans-serif; margin: 1.2em; color: #222; }}
#map {{ height: 520px; border: 1px solid #999; background: #f4f4f0; }}
table {{ border-collapse: collapse; font-size: 13px; margin: 0.5em 0 1em; }}
th, td {{ border: 1px solid #ccc; padding: 2px 6px; text-align: left; max-width: 42em; overflow-wrap: anywhere; }}
th {{ background: #eee; }}
.legend {{ background: white; padding: 6px 8px; font-size: 12px; line-height: 1.5; }}
.legend i {{ display: inline-block; width: 10px; height: 10px; border-radius: 5px; margin-right: 5px; }}
.legend b.line {{ display: inline-block; width: 14px; height: 2px; vertical-align: middle; margin-right: 3px; }}
</style></head><body>
<h1>{html.escape(title)}</h1>
<p>Vehicle class {html.escape(str(inv.get('vehicle_class', '')))}; period {html.escape(str((inv.get('period') or {}).get('start_utc', '')))} –
{html.escape(str((inv.get('period') or {}).get('end_utc', '')))}; RAIM {html.escape(str(inv['parameters'].get('raim')))},
P_MD {inv['parameters'].get('p_md')}, N_Th {inv['parameters'].get('n_th')}, T_c {inv['parameters'].get('tc_s')} s;
log SHA-256 {html.escape(str(inv['inputs'].get('log_sha256', ''))[:16])}…; invoice content SHA-256 {html.escape(str(inv.get('content_sha256', ''))[:16])}….
Epoch statuses (HAL {run.hal_m:g} m): {html.escape(', '.join(f'{k} {v}' for k, v in counts.items()))}.</p>
<details open><summary>What the epoch statuses mean</summary><ul>{meanings}</ul></details>
<div id="map"></div>
<h2 id="invoice">Invoice</h2>
{_table(invoice_columns, lines, "invoice")}
<h2>Seen but not charged</h2>
{_table(["geo-object", "entry (UTC)", "inside", "valid", "statuses"], missed) if missed else "<p>None.</p>"}
<h2>Findings (tamper and evasion signs)</h2>
{_table(["kind", "category", "start (UTC)", "end (UTC)", "evidence"], findings) if findings else "<p>None.</p>"}
{truth}
<details><summary>Per-epoch table ({len(epoch_rows)} epochs)</summary>
{_table(["time", "lat", "lon", "status", "HPL m", "HAL m", "P_FA", "t", "Th", "n", "excluded", "geo-object"], epoch_rows, "epochs")}
</details>
<script type="application/json" id="run-data">{_json_for_script(data)}</script>
<script>{_static("leaflet.js")}</script>
<script>
(function () {{
  var d = JSON.parse(document.getElementById('run-data').textContent);
  var map = L.map('map', {{ preferCanvas: true, zoomSnap: 0.25 }});
  if (d.tiles) L.tileLayer(d.tiles, {{ maxZoom: 19 }}).addTo(map);
  var charged = new Set(d.charged);
  var geo = L.geoJSON(d.geoobjects, {{ style: function (f) {{
      var c = charged.has(String(f.properties.id));
      return {{ color: c ? '#4575b4' : '#888888', weight: 1.5, fillOpacity: c ? 0.3 : 0.12 }}; }},
    onEachFeature: function (f, layer) {{ layer.bindTooltip(String(f.properties.id) + (charged.has(String(f.properties.id)) ? ' (charged)' : '')); }}
  }});
  var bounds = geo.getBounds();
  d.points.forEach(function (p) {{ bounds.extend([p[0], p[1]]); }});
  map.fitBounds(bounds.pad(0.05));  // the view first: layers are drawn into it
  geo.addTo(map);
  if (d.truth) L.polyline(d.truth, {{ color: '#000000', weight: 1 }}).addTo(map);
  d.points.forEach(function (p) {{
    L.circleMarker([p[0], p[1]], {{ radius: 3, stroke: false, fillOpacity: 0.9, fillColor: d.colours[p[2]] || '#000' }})
      .bindTooltip(p[2]).addTo(map);
  }});
  L.control.scale().addTo(map);
  var legend = L.control({{ position: 'bottomright' }});
  legend.onAdd = function () {{
    var div = L.DomUtil.create('div', 'legend');
    Object.keys(d.colours).forEach(function (k) {{ div.innerHTML += '<i style="background:' + d.colours[k] + '"></i>' + k + '<br>'; }});
    if (d.truth) div.innerHTML += '<b class="line" style="background:#000000"></b>truth<br>';
    return div;
  }};
  legend.addTo(map);
  document.body.setAttribute('data-map-ready', 'yes');
}})();
</script>
</body></html>
"""
