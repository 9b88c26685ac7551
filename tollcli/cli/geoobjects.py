"""``tollcli geoobjects build|check|info``: the geo-object database."""

from __future__ import annotations

import hashlib
import json
from typing import Annotated, Optional

import typer

from tollcli.geoobjects.build import CONNECT_TOL_M, TRIM_FACTOR
from tollcli.cli import options as opt
from tollcli.cli.console import note
from tollcli.errors import DataError, UsageError
from tollcli.io.writers import is_stream, write_text_atomic

app = typer.Typer(help="Build, check and inspect geo-objects: constant-HAL buffers around tolled roads.", no_args_is_help=True)


@app.command("build")
def build(
    roads: Annotated[str, typer.Argument(metavar="ROADS", help="Road network: GeoJSON, GeoPackage (.gpkg), Shapefile (.shp) or FlatGeobuf (.fgb) LineStrings with id, tolled, ...; or an OpenStreetMap file (.osm.pbf, .osm) with --tolled.")],
    output: opt.GeoJsonOutput = "-",
    out_fmt: opt.out_format("geojson", "geojson") = None,
    tolled: Annotated[Optional[list[str]], typer.Option("--tolled", help="OpenStreetMap: the tolled ways, e.g. 'highway=motorway,trunk', 'toll=yes', 'way:ID,ID', 'ref:E18' (repeat: any matches).")] = None,
    hal: Annotated[Optional[list[str]], typer.Option("--hal", help="Design HAL, m: 25 (exactly), 25-50 (the largest the roads kept clear of allow) or CLASS=VALUE for one road class (repeat). Default 25-50, the papers' range.")] = None,
    hal_max: Annotated[Optional[float], typer.Option("--hal-max", hidden=True, help="Before the design HAL: the largest HAL (now --hal 25-M).", min=0.1)] = None,
    hal_min: Annotated[Optional[float], typer.Option("--hal-min", help="Where no stretch of a section can have its design HAL: the smallest HAL to fall back to (listed); below it the section is skipped (listed), m. Default: no fallback, such a section is skipped (listed, with why).", min=0.0)] = None,
    n_th: Annotated[int, typer.Option("--n-th", help="The valid independent positions process will need per passage (its --n-th): with --tc and the section's speed (maxspeed, else its road class's), it sets the shortest stretch a geo-object is built on, speed × ((N_th − 1) · T_c + 1 s).", min=1, max=1000)] = 1,
    tc: Annotated[float, typer.Option("--tc", help="The correlation time process will use (its --tc), s: see --n-th.", min=0.1, max=86_400.0)] = 5.0,
    environment: Annotated[Optional[list[str]], typer.Option("--environment", help="The environment the roads run in, as the operator declares it: open (outside built-up land), urban, or CLASS=open|urban for one road class (repeat; a road's own 'environment' property wins). Recorded per geo-object: where a receiver gives no residuals (satellites only), the model level takes that environment's error model there; never weaker than what the residuals measure or process's --environment urban.")] = None,
    min_core: Annotated[Optional[float], typer.Option("--min-core", help="The shortest stretch of centre line a geo-object is built on, m (instead of the one --n-th and --tc give).", min=0.0, max=100_000.0)] = None,
    trim_factor: Annotated[float, typer.Option("--trim-factor", help="Junction ends are cut by this × HAL.", min=0.0)] = TRIM_FACTOR,
    connect_tol: Annotated[float, typer.Option("--connect-tol", help="Roads closer than this on one level meet (a junction), m.", min=0.0)] = CONNECT_TOL_M,
    as_json: Annotated[bool, typer.Option("--json", help="Summary (counts, coverage, sections below their design HAL, skipped sections and why) as JSON on stdout; needs -o FILE.")] = False,
    gantries: Annotated[Optional[str], typer.Option("--gantries", help="City charging: virtual gantries from this file — GeoJSON Points on the roads of ROADS (each made a line across its road) or two-point lines across them, or OpenStreetMap nodes tagged barrier=toll_booth / highway=toll_gantry. With --gantries or --zones only gantries and zones are built (docs/city.md).")] = None,
    zones: Annotated[Optional[str], typer.Option("--zones", help="City charging: charging zones from the Polygons of this GeoJSON file.")] = None,
    direction: Annotated[str, typer.Option("--direction", help="With --gantries: the direction charged where a point does not say: both, left_to_right (driving a road as it is drawn) or right_to_left.")] = "both",
    quiet: opt.Quiet = False,
) -> None:
    """Build geo-objects for a design HAL: along each tolled section, keep the stretches clear of every road it does not
    meet by 2 × HAL and buffer them by HAL; cut around the rest.

    Tolled roads are cut into sections at junctions (OpenStreetMap: shared nodes; other files: roads meeting on one
    level). A section cut around a near road keeps several parts, charged once per passage at its whole length. Where
    no stretch can have the design HAL, the section is skipped and said why — or, where --hal-min asks for it, the largest
    HAL down to it is used and listed. A stretch shorter than a passage needs to be seen (--n-th, --tc at the section's
    speed; --min-core) is no geo-object. Nothing is written that 'geoobjects check' or 'process' would refuse."""
    from tollcli.geoobjects.geojson_stream import gc_paused

    if out_fmt is not None and out_fmt.lower() != "geojson":
        raise UsageError(f"-f {out_fmt}: geo-objects are written as GeoJSON (what check, info and process read)")
    if not is_stream(output) and not output.lower().endswith((".geojson", ".json")):
        raise UsageError(f"{output}: geo-objects are written as GeoJSON (.geojson)")
    if as_json and output == "-":
        raise UsageError("--json writes the summary on stdout: give -o FILE for the geo-objects")
    if gantries is not None or zones is not None:
        _build_city(roads, output, gantries, zones, hal, hal_min, direction, as_json, quiet)
        return
    with gc_paused():  # millions of dicts and lists, no cycles: the collector would cost more than the build
        _build(roads, output, tolled, hal, hal_max, hal_min, trim_factor, connect_tol, as_json, quiet, (n_th, tc, min_core), environment)


def _build(roads, output, tolled, hal, hal_max, hal_min, trim_factor, connect_tol, as_json, quiet, seen_by=(1, 5.0, None),
           environment=None) -> None:  # fmt: skip
    from tollcli.geoobjects.design_hal import parse_design_hal
    from tollcli.geoobjects.check import HAL_MIN_CHECK_M, check_features
    from tollcli.geoobjects.store import precompile
    from tollcli.geoobjects.build import SeenBy, build_from_roads, fallbacks, roads_of
    from tollcli.geoobjects.osm import is_osm
    from tollcli.spatial import feature_collection_text

    gives_default = any("=" not in h for h in hal or [])
    if hal_max is not None and not gives_default:  # the option of earlier versions: the papers' range, capped at it
        hal = [*(hal or []), f"{min(25.0, hal_max):g}-{hal_max:g}"]
    design = parse_design_hal(hal)
    if is_osm(roads):
        from tollcli.geoobjects.osm_network import osm_roads
        from tollcli.geoobjects.osm import read_osm_roads

        network = osm_roads(read_osm_roads(roads), tolled or [])
    elif tolled:
        raise UsageError("--tolled selects ways of an OpenStreetMap file; a GeoJSON network says tolled per feature")
    else:
        network = roads_of(roads, connect_tol)
    from tollcli.geoobjects.declared_environment import parse_declared_environments

    doc, skipped = build_from_roads(network, roads, design, connect_tol, trim_factor, hal_min, shapely_geometry=True,
                                    seen=SeenBy(*seen_by), environments=parse_declared_environments(environment))  # fmt: skip
    del network  # the centre lines: not needed to write and compile the geo-objects
    if not doc["features"]:
        raise DataError(f"{roads}: no tolled section could be built ({len(skipped)} skipped: {skipped[0]['id']}: {skipped[0]['reason'] if skipped else ''})")
    refused = check_features(doc["features"], hal_min if hal_min is not None else HAL_MIN_CHECK_M)
    lowest = min(f["properties"]["hal_m"] for f in doc["features"])
    if refused:  # what check and process would say of the file, said before it is written
        more = f" and {len(refused) - 1} more" if len(refused) > 1 else ""
        raise DataError(f"{roads}: not writing geo-objects that check and process would refuse: {refused[0]}{more}")
    digest = hashlib.sha256()
    write_text_atomic(output, _hashed(feature_collection_text(doc), digest))
    if lowest >= HAL_MIN_CHECK_M:  # what process will load: compiled now (with a smaller HAL, load checks it)
        precompile(doc["features"], output, digest.hexdigest())
    below = fallbacks(doc)
    _tell(roads, doc, below, skipped, design.describe(), quiet)
    if as_json:
        hals = [f["properties"]["hal_m"] for f in doc["features"]]
        frames = sorted({f["properties"]["crs_metric"] for f in doc["features"]})
        typer.echo(json.dumps({"input": roads, "output": output, "geoobjects": len(hals), "hal_min_m": min(hals), "hal_max_m": max(hals),
                               "design_hal_m": design.describe(), "frames": frames, "below_design_hal": below, "skipped": skipped},
                              sort_keys=True))  # fmt: skip


def _build_city(roads, output, gantries, zones, hal, hal_min, direction, as_json, quiet) -> None:
    """Gantries across the roads of ROADS and zones from polygons → one GeoJSON of city geo-objects."""
    from tollcli.geoobjects.check import check_features
    from tollcli.geoobjects.city import DIRECTIONS
    from tollcli.geoobjects.gantry_build import build_gantries, build_zones, gantry_sites, road_lines
    import shapely

    from tollcli.spatial import feature_collection_text

    if direction not in DIRECTIONS:
        raise UsageError(f"--direction {direction!r}: one of {', '.join(DIRECTIONS)}")
    design = 50.0
    for h in hal or []:
        try:
            design = float(str(h).split("-")[-1])
        except ValueError:
            raise UsageError(f"--hal {h!r}: for gantries a HAL in metres (25) or a range (25-50: its largest)") from None
    features, skipped = [], []
    if gantries is not None:
        ids, lines = road_lines(roads)
        features, skipped = build_gantries(gantry_sites(gantries), ids, lines, design, 5.0 if hal_min is None else hal_min, direction)
    if zones is not None:
        features += build_zones(zones)
    if not features:
        raise DataError(f"{gantries or zones}: no gantry could be built ({skipped[0]['id']}: {skipped[0]['reason']})" if skipped
                        else f"{gantries or zones}: nothing to build")  # fmt: skip
    refused = check_features(features)
    if refused:
        raise DataError(f"{roads}: not writing geo-objects that check and process would refuse: {refused[0]}")
    for f in features:  # plain GeoJSON, coordinates to 1e-7° (1 cm)
        f["geometry"] = json.loads(shapely.to_geojson(shapely.set_precision(f["geometry"], 1e-7)))
    write_text_atomic(output, "".join(feature_collection_text({"type": "FeatureCollection", "features": features})))
    n_g = sum(f["properties"]["kind"] == "gantry" for f in features)
    n_z = len(features) - n_g
    note(f"{gantries or zones}: {n_g} gantr{'y' if n_g == 1 else 'ies'}, {n_z} zone{'' if n_z == 1 else 's'}"
         f"{f', {len(skipped)} skipped' if skipped else ''}", quiet)  # fmt: skip
    for s in skipped:
        note(f"{gantries}: {s['id']}: skipped: {s['reason']}", quiet)
    if as_json:
        typer.echo(json.dumps({"output": output, "gantries": n_g, "zones": len(features) - n_g, "skipped": skipped}, sort_keys=True))


def _hashed(pieces, digest):
    """The pieces of a text, each added to ``digest`` (its UTF-8 bytes) as it goes by."""
    for piece in pieces:
        digest.update(piece.encode("utf-8"))
        yield piece


def _tell(roads: str, doc: dict, below: list[dict], skipped: list[dict], design: str, quiet: bool) -> None:
    """The build's summary line, then each section below its design HAL and each section skipped (stderr)."""
    from tollcli.geoobjects.info import covered_lengths_m

    props = [f["properties"] for f in doc["features"]]
    hals = [p["hal_m"] for p in props]
    frames = {p["crs_metric"] for p in props}
    tolled, covered, _ = covered_lengths_m(props, skipped)
    more = f", {len(below)} below their design HAL" if below else ""
    more += f", {len(skipped)} sections skipped" if skipped else ""
    note(f"{roads}: {len(hals)} geo-objects, HAL {min(hals):g}–{max(hals):g} m (design {design}), covering "
         f"{covered / 1000:.3f} of {tolled / 1000:.3f} tolled km ({100 * covered / tolled:.1f} %), {len(frames)} metric "
         f"frame{'s' if len(frames) > 1 else ''}{more}", quiet)  # fmt: skip
    by_id = {p["id"]: p for p in props}
    for b in below:
        p = by_id[b["id"]]
        near = f" (cut around {', '.join(p['crossings'])})" if p.get("crossings") else ""
        note(f"{roads}: {b['id']}: HAL {b['hal_m']:g} m, below its design {b['design_hal_m'][0]:g} m: no stretch of it is "
             f"clear of other roads by {2 * b['design_hal_m'][0]:g} m{near}", quiet)  # fmt: skip
    for s in skipped:
        note(f"{roads}: {s['id']}: skipped: {s['reason']}", quiet)


@app.command("check")
def check(
    path: Annotated[str, typer.Argument(metavar="FILE", help="Geo-object file (GeoJSON polygons with id and hal_m).")],
    hal_max: Annotated[Optional[float], typer.Option("--hal-max", hidden=True, help="Before the design HAL: the largest HAL (now --hal 25-M).", min=0.1)] = None,
    hal_min: Annotated[float, typer.Option("--hal-min", help="Smallest acceptable HAL, m.", min=0.0)] = 5.0,
    as_json: Annotated[bool, typer.Option("--json", help="Findings as JSON on stdout.")] = False,
    quiet: opt.Quiet = False,
) -> None:
    """Report invalid geometry, missing or duplicate ids, overlaps, HAL below a minimum, wrong CRS (exit 1 if any)."""
    from tollcli.geoobjects.check import check_geoobjects

    findings = check_geoobjects(path, hal_min)
    if as_json:
        typer.echo(json.dumps([{"feature": f.feature, "problem": f.problem} for f in findings]))
    else:
        for finding in findings:
            typer.echo(f"{path}: {finding}")
    if findings:
        raise DataError(f"{path}: {len(findings)} problem{'s' if len(findings) > 1 else ''} found")


@app.command("info")
def info(
    path: Annotated[str, typer.Argument(metavar="FILE", help="Geo-object file (from 'tollcli geoobjects build').")],
    min_hal: Annotated[float, typer.Option("--min-hal", help="Also give the tolled length covered by geo-objects of at least this HAL, m.", min=0.0)] = 25.0,
    as_json: Annotated[bool, typer.Option("--json", help="Everything as JSON on stdout.")] = False,
    quiet: opt.Quiet = False,
) -> None:
    """What a geo-object file holds: counts, HAL histogram, the share of the tolled length covered, and for each
    geo-object its HAL, design, parts, what holds its HAL and the nearest road kept clear of (and how far away it is)."""
    from tollcli.geoobjects.info import geoobject_info

    summary = geoobject_info(path, min_hal)
    if as_json:
        typer.echo(json.dumps(summary, sort_keys=True))
        return
    h = summary["hal_m"]
    plural = {"gantry": "gantries", "zone": "zones", "section": "sections"}
    kinds = ", ".join(f"{n} {plural.get(k, k) if n > 1 else k}" for k, n in summary["kinds"].items())
    kinds = f" ({kinds})" if set(summary["kinds"]) != {"section"} else ""
    lines = [f"{path}: {summary['geoobjects']} geo-objects{kinds}, {summary['sections_skipped']} tolled sections skipped at build",
             f"HAL: {h['min']:g}–{h['max']:g} m, median {h['median']:g} m; below their design HAL: {len(summary['below_design_hal'])}"]
    for b in summary["hal_histogram"]:
        if b["count"]:
            upper = f"{b['to_m']:g}" if b["to_m"] is not None else "…"
            lines.append(f"  HAL {b['from_m']:g}–{upper} m: {b['count']}")
    tolled = summary["tolled_length_m"]
    if tolled:
        lines.append(f"covered: {summary['covered_length_m'] / 1000:.3f} of {tolled / 1000:.3f} tolled km ({100 * summary['covered_share']:.1f} %); "
                     f"by HAL ≥ {min_hal:g} m: {summary['covered_at_min_hal_m'] / 1000:.3f} km ({100 * summary['covered_share_at_min_hal']:.1f} %)")  # fmt: skip
    city = set(summary["kinds"]) != {"section"}  # a kind column only where there is more than sections (scripts read the table)
    lines.append("id\t" + ("kind\t" if city else "") + "hal_m\tdesign_m\tlength_m\tsection_m\tparts\thal_bound\tnearest_road\tnearest_road_m")
    for r in summary["features"]:
        design = r["design_hal_m"]
        design = (f"{design[0]:g}" if design[0] == design[1] else f"{design[0]:g}-{design[1]:g}") if isinstance(design, list) else ""
        distance = f"{r['nearest_road_m']:g}" if r["nearest_road_m"] is not None else ""
        lines.append(f"{r['id']}\t{r['kind'] + chr(9) if city else ''}{r['hal_m']:g}\t{design}\t{r['length_m']:g}\t{r['section_length_m']:g}\t{r['parts']}\t"
                     f"{r['hal_bound'] or ''}\t{r['nearest_road'] or ''}\t{distance}")
    typer.echo("\n".join(lines))


@app.command("compile")
def compile_store(
    path: Annotated[str, typer.Argument(metavar="FILE", help="Geo-object file (GeoJSON from 'tollcli geoobjects build' or elsewhere).")],
    as_json: Annotated[bool, typer.Option("--json", help="What was compiled (file, SHA-256, geo-objects, store folder, its manifest digest and size, seconds) as JSON on stdout.")] = False,
    quiet: opt.Quiet = False,
) -> None:
    """Compile a geo-object file into its store ahead of the logs: checked, projected, indexed and kept as arrays in the
    cache ($TOLLCLI_CACHE_DIR/geoobjects/SHA-256.vN), which every later process, batch and worker maps instead of
    parsing the file. 'geoobjects build' compiles what it writes; a file made elsewhere is compiled by its first
    process, or here (exit 1 if check would refuse it). Nothing to do when the store exists."""
    import time

    from tollcli.cache import cache_dir
    from tollcli.geoobjects.store import load_geoobjects

    if cache_dir() is None:
        raise UsageError("there is no cache to compile into (TOLLCLI_CACHE_DIR=off, or a folder others can write)")
    start = time.perf_counter()
    geo = load_geoobjects(path)
    seconds = time.perf_counter() - start
    if geo.store is None:
        raise DataError(f"{path}: the store could not be written in {cache_dir()}")
    size = sum(f.stat().st_size for f in geo.store.glob("*.npy"))  # (the arrays: other files come and go with readers)
    summary = {"file": path, "sha256": geo.source_sha256, "geoobjects": len(geo.ids), "store": str(geo.store),
               "store_sha256": geo.store_sha256, "store_bytes": size, "seconds": round(seconds, 3)}  # fmt: skip
    if as_json:
        typer.echo(json.dumps(summary, sort_keys=True))
    else:
        note(f"{path}: {len(geo.ids)} geo-objects in {geo.store} ({size / 1e6:.1f} MB, {seconds:.1f} s)", quiet)
