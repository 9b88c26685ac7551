"""``tollcli geoobjects build|check``: the geo-object database."""

from __future__ import annotations

import json
from typing import Annotated, Optional

import typer

from tollcli.charging.geoobjects import CONNECT_TOL_M, HAL_MAX_M, TRIM_FACTOR, build_from_roads, build_geoobjects, check_geoobjects
from tollcli.cli import options as opt
from tollcli.cli.console import warn
from tollcli.errors import DataError, UsageError
from tollcli.io.writers import write_text_atomic

app = typer.Typer(help="Build and check geo-objects: constant-HAL buffers around tolled roads.", no_args_is_help=True)


@app.command("build")
def build(
    roads: Annotated[str, typer.Argument(metavar="ROADS", help="Road network: GeoJSON LineStrings with id, tolled, ...; or an OpenStreetMap file (.osm.pbf, .osm) with --tolled.")],
    output: opt.GeoJsonOutput = "-",
    tolled: Annotated[Optional[list[str]], typer.Option("--tolled", help="OpenStreetMap: the tolled ways, e.g. 'highway=motorway,trunk', 'toll=yes', 'way:ID,ID', 'ref:E18' (repeat: any matches).")] = None,
    hal_max: Annotated[float, typer.Option("--hal-max", help="Largest HAL, m.", min=0.1)] = HAL_MAX_M,
    hal_min: Annotated[float, typer.Option("--hal-min", help="OpenStreetMap: sections whose HAL would fall below this are cut around the near road, or skipped (listed), m.", min=0.0)] = 5.0,
    trim_factor: Annotated[float, typer.Option("--trim-factor", help="Junction ends are cut by this × HAL.", min=0.0)] = TRIM_FACTOR,
    connect_tol: Annotated[float, typer.Option("--connect-tol", help="Roads closer than this touch (a junction), m.", min=0.0)] = CONNECT_TOL_M,
    as_json: Annotated[bool, typer.Option("--json", help="Summary (counts, skipped sections and why) as JSON on stdout; needs -o FILE.")] = False,
    quiet: opt.Quiet = False,
) -> None:
    """Buffer each tolled road by HAL = min(HAL_max, half the distance to the nearest road it does not meet).

    From OpenStreetMap, tolled ways are merged into sections between junctions; roads meet only at a shared
    node, so a road crossing on a bridge or in a tunnel is cut around, never connected."""
    from tollcli.readers.osm import is_osm

    if output != "-" and not output.lower().endswith((".geojson", ".json")):
        raise UsageError(f"{output}: geo-objects are written as GeoJSON (.geojson)")
    if as_json and output == "-":
        raise UsageError("--json writes the summary on stdout: give -o FILE for the geo-objects")
    skipped: list[dict] = []
    if is_osm(roads):
        from tollcli.charging.osm_network import osm_roads
        from tollcli.readers.osm import read_osm_roads

        doc, skipped = build_from_roads(osm_roads(read_osm_roads(roads), tolled or []), roads, hal_max, connect_tol,
                                        trim_factor, hal_min_m=hal_min)  # fmt: skip
        if not doc["features"]:
            raise DataError(f"{roads}: no tolled section could be built ({len(skipped)} skipped: {skipped[0]['reason'] if skipped else ''})")
    elif tolled:
        raise UsageError("--tolled selects ways of an OpenStreetMap file; a GeoJSON network says tolled per feature")
    else:
        doc = build_geoobjects(roads, hal_max, connect_tol, trim_factor)
    write_text_atomic(output, json.dumps(doc, separators=(",", ":"), sort_keys=True) + "\n")
    hals = [f["properties"]["hal_m"] for f in doc["features"]]
    frames = sorted({f["properties"]["crs_metric"] for f in doc["features"]})
    more = f", {len(skipped)} sections skipped (too short or a road too near: --json lists them)" if skipped else ""
    warn(f"{roads}: {len(hals)} geo-objects, HAL {min(hals):g}–{max(hals):g} m, {len(frames)} metric frame{'s' if len(frames) > 1 else ''}{more}", quiet)
    if as_json:
        typer.echo(json.dumps({"input": roads, "output": output, "geoobjects": len(hals), "hal_min_m": min(hals), "hal_max_m": max(hals),
                               "frames": frames, "skipped": skipped}, sort_keys=True))  # fmt: skip


@app.command("check")
def check(
    path: Annotated[str, typer.Argument(metavar="FILE", help="Geo-object file (GeoJSON polygons with id and hal_m).")],
    hal_min: Annotated[float, typer.Option("--hal-min", help="Smallest acceptable HAL, m.", min=0.0)] = 5.0,
    as_json: Annotated[bool, typer.Option("--json", help="Findings as JSON on stdout.")] = False,
) -> None:
    """Report invalid geometry, missing or duplicate ids, overlaps, HAL below a minimum, wrong CRS (exit 1 if any)."""
    findings = check_geoobjects(path, hal_min)
    if as_json:
        typer.echo(json.dumps([{"feature": f.feature, "problem": f.problem} for f in findings]))
    else:
        for finding in findings:
            typer.echo(f"{path}: {finding}")
    if findings:
        raise DataError(f"{path}: {len(findings)} problem{'s' if len(findings) > 1 else ''} found")
