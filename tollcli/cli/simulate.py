"""``tollcli simulate``: a synthetic drive with known truth (logs, truth, manifest) into a folder."""

from __future__ import annotations

import datetime as dt
import json
import shlex
from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note, progress
from tollcli.errors import UsageError
from tollcli.simulate.drive import SimConfig
from tollcli.simulate.errors import FaultPlan
from tollcli.simulate.route import PERPIGNAN, along_route, load_route, straight
from tollcli.simulate.run import write_drive
from tollcli.simulate.streets import ENVIRONMENTS


def _floats(text: str, what: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"{what}: expected comma-separated numbers, got {text!r}") from None


def _command(ctx: typer.Context) -> str:
    """The command line that makes these files, rebuilt from the options (defaults left out)."""
    words = ["tollcli", "simulate"]
    for param in ctx.command.params:
        if param.name in ("quiet", "json_summary", "output") or not param.opts:
            continue
        value = ctx.params.get(param.name)
        if value is None or value == param.default or (isinstance(value, bool) and not value):
            continue
        if isinstance(value, dt.datetime):
            value = value.strftime("%Y-%m-%dT%H:%M:%S")
        words += [param.opts[-1] if param.opts[-1].startswith("--") else param.opts[0], shlex.quote(f"{value:g}" if isinstance(value, float) else str(value))]
    return " ".join(words + ["-o", shlex.quote(str(ctx.params["output"]))])


def _route_lines(route: str, via: str | None, path_from: str | None, path_to: str | None, tour_m: float | None = None,
                 seed: int = 0) -> list:  # fmt: skip
    """The lines to drive: a GeoJSON route (optionally --via ids) or an OpenStreetMap one (--via ways, --from/--to,
    --from and --tour)."""
    from tollcli.geoobjects.osm import is_osm

    if not is_osm(route):
        if path_from or tour_m:
            raise UsageError("--from/--to and --tour need an OpenStreetMap --route (.osm.pbf, .osm)")
        return load_route(route, via.split(",") if via else None)
    from tollcli.simulate.osm_route import route_by_ways, shortest_route, tour

    if tour_m:
        start = _floats(path_from, "--from") if path_from else []
        if len(start) != 2 or path_to or via:
            raise UsageError("--tour starts at --from LAT,LON, without --to or --via")
        return tour(route, (start[0], start[1]), tour_m, seed=seed)
    if path_from:
        ends = [_floats(p, name) for p, name in ((path_from, "--from"), (path_to, "--to"))]
        if any(len(e) != 2 for e in ends):
            raise UsageError("--from and --to are LAT,LON in degrees")
        return shortest_route(route, tuple(ends[0]), tuple(ends[1]))
    if not via:
        raise UsageError(f"{route}: an OpenStreetMap route needs --via WAY,WAY… or --from LAT,LON --to LAT,LON")
    return route_by_ways(route, [v.strip() for v in via.split(",") if v.strip()])


#: output rates a receiver logs at, Hz
RATES_HZ = (1.0, 2.0, 5.0, 10.0, 20.0)


def simulate(
    ctx: typer.Context,
    output: Annotated[str, typer.Option("-o", "--output", help="Folder for the drive's files (created if needed).")],
    route: Annotated[Optional[str], typer.Option("--route", help="GeoJSON with the LineString(s) to drive, or an OpenStreetMap file (.osm.pbf, .osm); without it a straight drive from --start along --heading.")] = None,
    via: Annotated[Optional[str], typer.Option("--via", help="Comma-separated road ids of --route to drive, in order (OpenStreetMap: way ids).")] = None,
    path_from: Annotated[Optional[str], typer.Option("--from", help="LAT,LON: with an OpenStreetMap --route, drive the shortest path from here to --to.")] = None,
    path_to: Annotated[Optional[str], typer.Option("--to", help="LAT,LON: the end of the shortest path (with --from).")] = None,
    tour_m: Annotated[Optional[float], typer.Option("--tour", help="With an OpenStreetMap --route and --from: drive shortest paths to random places of the map (each at least 600 m away; --seed picks them) until this many metres, a town drive.", min=1.0)] = None,
    turn_radius: Annotated[Optional[float], typer.Option("--turn-radius", help="With --route: round its corners to arcs of this radius (m) and slow for them, turning at up to 2 m/s² sideways (braking and pulling away at 1.5 m/s²); without it the vehicle takes corners at full speed.", min=1.0)] = None,
    geo: Annotated[Optional[str], typer.Option("--geo", help="Geo-objects: the truth then lists those really driven.")] = None,
    env: Annotated[str, typer.Option("--env", help="Street environment (paper 001 Table I): urban, rural or open.")] = "urban",
    constellations: Annotated[str, typer.Option("--constellations", help="Nominal constellations: gps, galileo or gps,galileo.")] = "gps,galileo",
    duration: Annotated[Optional[float], typer.Option("--duration", help="Seconds to drive (default: the whole route, or 600 s straight).", min=0.0)] = None,
    speed: Annotated[float, typer.Option("--speed", help="Vehicle speed, m/s (13.89 = 50 km/h).", min=0.1)] = 13.89,
    rate: Annotated[float, typer.Option("--rate", help="Output rate, Hz (1, 2, 5, 10 or 20).")] = 1.0,
    start: Annotated[str, typer.Option("--start", help="LAT,LON of a straight drive's start, degrees.")] = f"{PERPIGNAN[0]:.6f},{PERPIGNAN[1]:.6f}",
    heading: Annotated[float, typer.Option("--heading", help="Heading of a straight drive, degrees from north.", min=-360.0, max=360.0)] = 0.0,
    start_utc: Annotated[dt.datetime, typer.Option("--start-utc", formats=["%Y-%m-%dT%H:%M:%S"], help="UTC time of the first epoch.")] = dt.datetime(2026, 3, 2, 8, 0, 0),
    nav: Annotated[Optional[str], typer.Option("--nav", help="RINEX navigation file: satellites from its broadcast ephemerides instead of the nominal constellations.")] = None,
    iono: opt.Iono = "single",
    tc: Annotated[float, typer.Option("--tc", help="Correlation time of the pseudorange errors, s (0 = white).", min=0.0)] = 5.0,
    cn0: Annotated[float, typer.Option("--cn0", help="C/N0 of every received satellite, dB-Hz (the thesis uses 30).", min=0.0, max=70.0)] = 30.0,
    fault_bias: Annotated[float, typer.Option("--fault-bias", help="Bias added to the faulty satellite's pseudorange, m.", min=-1e5, max=1e5)] = 0.0,
    fault_at: Annotated[Optional[str], typer.Option("--fault-at", help="Comma-separated fault start times, s from the start.")] = None,
    fault_prob: Annotated[float, typer.Option("--fault-prob", help="Share of the time in fault episodes (random starts).", min=0.0, max=1.0)] = 0.0,
    fault_duration: Annotated[float, typer.Option("--fault-duration", help="Length of each fault episode, s.", min=0.0)] = 10.0,
    fault_sv: Annotated[Optional[str], typer.Option("--fault-sv", help="Faulty satellite, e.g. G05 or E11 (default: the visible one with the largest slope).")] = None,
    jam_at: Annotated[Optional[str], typer.Option("--jam-at", help="Comma-separated jamming start times, s from the start.")] = None,
    jam_duration: Annotated[float, typer.Option("--jam-duration", help="Length of each jamming episode, s.", min=0.0)] = 30.0,
    jam_db: Annotated[float, typer.Option("--jam-db", help="C/N0 lost by every satellite while jammed, dB.", min=0.0)] = 0.0,
    track_min: Annotated[float, typer.Option("--track-min", help="Satellites below this C/N0 are not tracked, dB-Hz.", min=0.0, max=70.0)] = 20.0,
    lateral_bias: Annotated[float, typer.Option("--lateral-bias", help="A receiver-level position offset to the right of travel, m (negative: left); invisible to RAIM.", min=-1e4, max=1e4)] = 0.0,
    lateral_bias_at: Annotated[Optional[str], typer.Option("--lateral-bias-at", help="Comma-separated start times of the offset, s.")] = None,
    lateral_bias_duration: Annotated[float, typer.Option("--lateral-bias-duration", help="How long each offset lasts, s.", min=0.0)] = 60.0,
    stop_at: Annotated[Optional[str], typer.Option("--stop-at", help="Comma-separated times the vehicle stops in traffic, s from the start (it brakes and pulls away at 1.5 m/s²).")] = None,
    stop_duration: Annotated[float, typer.Option("--stop-duration", help="How long each stop lasts, s.", min=0.0)] = 180.0,
    nlos: Annotated[bool, typer.Option("--nlos", help="City reflections: a satellite the buildings block is received by reflection part of the time, weaker and late (an excess path of ~30–70 m correlated over 30 s); C/N0 rises with elevation.")] = False,
    odometry: Annotated[bool, typer.Option("--odometry", help="The vehicle's odometry (wheel speed with a 1 % scale error, yaw rate with a 0.002 rad/s bias), written with the pseudoranges as libRSF text (drive-librsf.txt, truth-librsf.txt).")] = False,
    sensor_fault_at: Annotated[Optional[str], typer.Option("--sensor-fault-at", help="Comma-separated times the odometry goes wrong, s from the start (with --odometry: --odometer-step, --gyro-step).")] = None,
    sensor_fault_duration: Annotated[float, typer.Option("--sensor-fault-duration", help="How long each odometry fault lasts, s.", min=0.0)] = 60.0,
    odometer_step: Annotated[float, typer.Option("--odometer-step", help="The odometer's scale error added during a sensor fault (0.1: it reads 10 % more; -0.9…10).", min=-0.9, max=10.0)] = 0.0,
    gyro_step: Annotated[float, typer.Option("--gyro-step", help="The gyro's bias added during a sensor fault, rad/s (±1).", min=-1.0, max=1.0)] = 0.0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of every random draw: the same seed gives the same files.")] = 0,
    json_summary: opt.JsonSummary = False,
    quiet: opt.Quiet = False,
) -> None:
    """Simulate a drive with known truth: NMEA log, GSDC derived CSV, truth trajectory, driven geo-objects.

    Satellites: nominal Walker GPS 24 and Galileo 27, 5° mask; only satellites in
    line of sight past the street's buildings are received; errors from the
    nominal model with correlation time --tc; optional faults. Example:

      tollcli simulate --route geoobjects/example-roads.geojson --via A9-N1,A9-N2
      --geo geoobjects/example-geoobjects.geojson --env rural --seed 1 -o drive/
    """
    if env not in ENVIRONMENTS:
        raise UsageError(f"--env {env!r}: one of {', '.join(ENVIRONMENTS)}")
    if rate not in RATES_HZ:
        raise UsageError(f"--rate {rate:g}: one of {', '.join(f'{r:g}' for r in RATES_HZ)}")
    names = [c.strip().lower() for c in constellations.split(",") if c.strip()]
    if not names or any(n not in ("gps", "galileo") for n in names):
        raise UsageError(f"--constellations {constellations!r}: gps, galileo or gps,galileo")
    if iono not in ("single", "sbas", "iono-free"):
        raise UsageError(f"--iono {iono!r}: single, sbas or iono-free")
    if fault_sv and not (fault_sv[:1].upper() in "GE" and fault_sv[1:].isdigit()):
        raise UsageError(f"--fault-sv {fault_sv!r}: like G05 or E11")
    if not tour_m and ((path_from is None) != (path_to is None) or (path_from and (via or not route))):
        raise UsageError("--from and --to go together, with an OpenStreetMap --route and without --via")
    if (tour_m or turn_radius) and not route:
        raise UsageError("--tour and --turn-radius need a --route")
    if sensor_fault_at and not odometry:
        raise UsageError("--sensor-fault-at injects faults into the odometry: give --odometry too")
    stops = [(at, stop_duration) for at in _floats(stop_at, "--stop-at")] if stop_at else []
    if any(at < 0 for at, _ in stops):
        raise UsageError(f"--stop-at {stop_at!r}: times from the start, s ≥ 0")
    if route:
        trajectory = along_route(_route_lines(route, via, path_from, path_to, tour_m, seed), speed, rate, duration, stops=stops,
                                 turn_radius_m=turn_radius)  # fmt: skip
    else:
        lat_lon = _floats(start, "--start")
        if len(lat_lon) != 2 or not (-90 <= lat_lon[0] <= 90 and -180 <= lat_lon[1] <= 180):
            raise UsageError(f"--start {start!r}: LAT,LON in degrees")
        trajectory = straight(lat_lon[0], lat_lon[1], heading, speed, 600.0 if duration is None else duration, rate, stops=stops)
    faults = FaultPlan(bias_m=fault_bias, at_s=_floats(fault_at, "--fault-at") if fault_at else [], p_fault=fault_prob,
                       duration_s=fault_duration, sv=fault_sv.upper() if fault_sv else None)  # fmt: skip
    config = SimConfig(constellations=names, env=env, iono=iono, cn0_dbhz=cn0, tc_s=tc, faults=faults, seed=seed,
                       start_utc=start_utc.replace(tzinfo=dt.UTC), jam_at_s=_floats(jam_at, "--jam-at") if jam_at else [],
                       jam_duration_s=jam_duration, jam_db=jam_db, track_min_dbhz=track_min, nav_path=nav,
                       lateral_bias_m=lateral_bias, lateral_bias_at_s=_floats(lateral_bias_at, "--lateral-bias-at") if lateral_bias_at else [],
                       lateral_bias_duration_s=lateral_bias_duration, nlos=nlos, odometry=odometry,
                       sensor_fault_at_s=_floats(sensor_fault_at, "--sensor-fault-at") if sensor_fault_at else [],
                       sensor_fault_duration_s=sensor_fault_duration, odo_scale_step=odometer_step, gyro_bias_step_radps=gyro_step)  # fmt: skip
    command = _command(ctx)
    with progress("simulating", quiet) as advance:
        manifest = write_drive(trajectory, config, output, geo=geo, command=command, progress=advance)
    counts = manifest["counts"]
    note(f"{output}: {counts['epochs']} epochs, {counts['fixes']} fixes, {counts['faulty_epochs']} faulty, "
         f"≥ 5 satellites {manifest['visible_satellites']['ge5']:.1%}", quiet)  # fmt: skip
    if json_summary:
        typer.echo(json.dumps({"output": output, **manifest}, sort_keys=True))
