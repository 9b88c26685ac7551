"""``tollcli geoobjects build|check``: the geo-object database."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from tollcli.charging.geoobjects import CONNECT_TOL_M, HAL_MAX_M, TRIM_FACTOR, build_geoobjects, check_geoobjects
from tollcli.cli import options as opt
from tollcli.cli.console import warn
from tollcli.errors import DataError, UsageError
from tollcli.io.writers import write_text_atomic

app = typer.Typer(help="Build and check geo-objects: constant-HAL buffers around tolled roads.", no_args_is_help=True)


@app.command("build")
def build(
    roads: Annotated[str, typer.Argument(metavar="ROADS", help="Road network: GeoJSON LineStrings with id, tolled, ...")],
    output: opt.GeoJsonOutput = "-",
    hal_max: Annotated[float, typer.Option("--hal-max", help="Largest HAL, m.", min=0.1)] = HAL_MAX_M,
    trim_factor: Annotated[float, typer.Option("--trim-factor", help="Junction ends are cut by this × HAL.", min=0.0)] = TRIM_FACTOR,
    connect_tol: Annotated[float, typer.Option("--connect-tol", help="Roads closer than this touch (a junction), m.", min=0.0)] = CONNECT_TOL_M,
    quiet: opt.Quiet = False,
) -> None:
    """Buffer each tolled road by HAL = min(HAL_max, half the distance to the nearest road it does not meet)."""
    if output != "-" and not output.lower().endswith((".geojson", ".json")):
        raise UsageError(f"{output}: geo-objects are written as GeoJSON (.geojson)")
    doc = build_geoobjects(roads, hal_max, connect_tol, trim_factor)
    write_text_atomic(output, json.dumps(doc, separators=(",", ":"), sort_keys=True) + "\n")
    hals = [f["properties"]["hal_m"] for f in doc["features"]]
    warn(f"{roads}: {len(hals)} geo-objects, HAL {min(hals):g}–{max(hals):g} m, CRS {doc['features'][0]['properties']['crs_metric']}", quiet)


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
