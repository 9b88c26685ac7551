"""Option definitions shared by the commands (one place, as in rasterio's rio)."""

from __future__ import annotations

import datetime as _dt
from typing import Annotated, Literal, Optional

import typer

#: the choices of the options below, checked by the parser (tests/test_cli_conventions.py holds them equal to the
#: rooms' own tuples: RAIM modes, environments, integrity levels, σ models, ionosphere models, input kinds, policies)
RAIM_MODES = ("ss", "etc", "classic")
ENVIRONMENTS = ("auto", "open", "urban")
INTEGRITY_LEVELS = ("auto", "residual", "receiver", "covariance", "model")
SIGMA_MODELS = ("nominal", "urban", "rural", "constant", "input")
IONO_MODELS = ("single", "sbas", "iono-free")
INPUT_KINDS = ("auto", "nmea", "ubx-nav", "gpsd-json", "gpsd-binary", "rtklib-pos", "gsdc-derived", "rinex", "gnsslogger", "device-gnss",
               "ubx", "librsf")  # fmt: skip
POLICIES = ("raim", "raim+speed", "raim+mm", "all")
POSITIONINGS = ("auto", "smoothed", "filtered", "snapshot")

LogArg = Annotated[
    str,
    typer.Argument(metavar="LOG", help="Receiver log: a path, a .gz path, or - for stdin.", show_default=False),
]


def output_option(help_text: str):
    """A command's ``-o/--output`` option with its own help."""
    return Annotated[str, typer.Option("-o", "--output", help=help_text)]


Output = output_option("Output file; the format follows -f or the extension (.csv, .parquet, .geojson, .geojsonl, .json); - is stdout (CSV unless -f).")
JsonOutput = output_option("Output file, JSON (.json); - is stdout.")
InvoiceOutput = output_option("Invoice file: .json (the sealed invoice) or .csv (its lines, one row each); - is stdout (JSON unless -f csv).")
FindingsOutput = output_option("Findings file: .json (the document), .csv, .geojson or .geojsonl (one per finding); - is stdout (JSON unless -f).")
GeoJsonOutput = output_option("Geo-object file, GeoJSON (.geojson or .json); - is stdout.")


def require_json(output: str) -> str:
    """UsageError unless ``output`` is ``-`` or a .json file (commands that write one JSON document)."""
    from tollcli.errors import UsageError
    from tollcli.io.writers import is_stream

    if not is_stream(output) and not output.lower().endswith(".json"):
        raise UsageError(f"{output}: this command writes JSON: name the file .json (or - for stdout)")
    return output
InputFormat = Annotated[Literal[INPUT_KINDS], typer.Option("--input-format", help="Input: auto, nmea, ubx-nav (u-blox NAV-PVT/SOL/POSLLH, NAV-SAT/SVINFO with prRes, NAV-DOP, NAV-PL, HNR-PVT), gpsd-json (gpspipe -w, gpsdecode: TPV, SKY, GST), gpsd-binary (a binary protocol gpsd decodes — SiRF, GREIS, Oncore, Zodiac, …: read through gpsdecode, which must be installed), rtklib-pos (RTKLIB .pos solutions: Q, sdn/sde/sdne), gsdc-derived (GSDC 2021), rinex (observation file), gnsslogger (Android GnssLogger Raw), device-gnss (GSDC 2022/2023 device_gnss.csv), ubx (u-blox RXM-RAWX), librsf (libRSF text: smartLoc pseudorange3/odom3).")]
Nav = Annotated[Optional[list[str]], typer.Option("--nav", help="Navigation file, RINEX 2 or 3 (GPS, Galileo, BeiDou, GLONASS): the orbits for rinex and gnsslogger input; replaces the file's own satellites for device-gnss and ubx. Repeatable: several files are read as one (a day's files of each system, consecutive days).")]


def nav_files(nav) -> str | tuple[str, ...] | None:
    """``--nav`` as the rooms below take it: None, one path (recorded as before), or several."""
    if nav is None or isinstance(nav, str):
        return nav
    nav = tuple(nav)
    return None if not nav else nav[0] if len(nav) == 1 else nav


def check_input_format(fmt: str) -> str:
    """UsageError for an --input-format that is not one of INPUT_KINDS."""
    from tollcli.errors import UsageError
    from tollcli.io.sources import INPUT_KINDS

    if fmt not in INPUT_KINDS:
        raise UsageError(f"--input-format {fmt}: use one of {', '.join(INPUT_KINDS)}")
    return fmt


def out_format(formats: str, default: str) -> object:
    """The ``-f/--format`` option of a command writing ``formats`` (``default`` when neither -f nor -o's extension says)."""
    return Annotated[Optional[str], typer.Option(
        "-f", "--format", metavar="FORMAT", show_default=False,
        help=f"Output format: {formats} (GDAL's driver names too); default: -o's extension, else {default}.")]


TableFormat = out_format("csv, parquet, geojson, geojsonseq or json", "csv")
InvoiceFormat = out_format("json or csv", "json")
FindingsFormat = out_format("json (the document), csv, geojson or geojsonseq (one record per finding)", "json")


def split_format(fmt: str | None, input_format: str) -> tuple[str | None, str]:
    """(output format, input format) from ``-f/--format`` and ``--input-format``.

    ``--format`` named the input before it named the output (as in ogr2ogr and rio): an input kind given there
    (``--format nmea``) is still read as the input; the two value sets are disjoint.
    """
    from tollcli.errors import UsageError
    from tollcli.io.sources import INPUT_KINDS

    if fmt is not None and fmt in INPUT_KINDS and fmt != "auto":
        if input_format not in ("auto", fmt):
            raise UsageError(f"--format {fmt} and --input-format {input_format}: give the input's format once, with --input-format")
        return None, fmt
    return fmt, check_input_format(input_format)


OsnmaMerkle = Annotated[Optional[str], typer.Option("--osnma-merkle", help="The Galileo OSNMA Merkle tree (GSC XML) to authenticate a u-blox log's navigation data with; default: OSNMA_MerkleTree.xml beside the log, if there.")]
OsnmaPublicKey = Annotated[Optional[list[str]], typer.Option("--osnma-public-key", help="An OSNMA public key file (GSC XML), repeatable; default: OSNMA_PublicKey*.xml beside the log (a key is used only when the Merkle tree holds it; without one it comes from the signal).")]
RequireAuthenticated = Annotated[bool, typer.Option("--require-authenticated", help="A position counts only when its navigation data were authenticated by Galileo OSNMA (every used satellite, or ≥ 4 whose own position agrees with the fix); others are 'unauthenticated' or 'subset_disagrees'.")]

Strict = Annotated[
    bool,
    typer.Option("--strict", help="Stop at the first unusable line (bad checksum, malformed, not NMEA) with its line number."),
]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress and no summary on stderr.")]
JsonSummary = Annotated[
    bool,
    typer.Option("--json", help="Print a machine-readable summary as JSON on stdout (needs -o FILE)."),
]
def start_time_value(value: str | None) -> str | None:
    """``--start-time``: an ISO 8601 date and time with its UTC offset (``Z`` or ``+02:00``), written back in UTC."""
    if value is None:
        return None
    try:
        t = _dt.datetime.fromisoformat(value.replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError:
        raise typer.BadParameter(f"{value!r} is not a date and time (write it as 2019-06-01T08:00:00+02:00)") from None
    if t.tzinfo is None:
        raise typer.BadParameter(f"{value!r} has no UTC offset (write Z or +02:00 after the time)")
    if not 1980 <= t.astimezone(_dt.timezone.utc).year <= 2200:
        raise typer.BadParameter(f"{value!r} is not between 1980 and 2200")
    return t.astimezone(_dt.timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


StartTime = Annotated[
    Optional[str],
    typer.Option("--start-time", callback=start_time_value, help="When a log whose times are seconds from its start (libRSF) "
                 "began: an ISO 8601 date and time with its UTC offset (2019-06-01T08:00:00+02:00). An invoice needs it: "
                 "time bands, day types and the period are priced on this clock."),
]
DateOpt = Annotated[
    Optional[_dt.datetime],
    typer.Option("--date", formats=["%Y-%m-%d"], help="UTC date of the first epoch, for logs without RMC/ZDA dates (YYYY-MM-DD)."),
]

#: the smallest probability an option takes: below it 1 − p is 1 in floating point and χ² quantiles lose their meaning
#: (``--p-sat 1e-320`` was taken as given)
PROBABILITY_FLOOR = 1e-15

RaimMode = Annotated[Literal[RAIM_MODES], typer.Option("--raim", help="RAIM: ss (solution separation over every satellite and constellation left out: several faults at once, HPL from the fault modes; the default), etc (paper 001's toll RAIM: HPL = HAL, P_FA per epoch, one fault) or classic (paper 001's civil-aviation RAIM: fixed P_FA, HPL ≤ HAL, one fault).")]
Positioning = Annotated[Literal[POSITIONINGS], typer.Option("--positioning", help="Pseudorange logs: where each position comes from. smoothed: a robust filter with the log's odometry (or a GNSS-only motion model), run forward and backward over the whole trip and combined (covariance intersection), HPL from its covariance with the noise the log's own residuals show, a fault where the two runs disagree; filtered: the forward filter's positions (what an on-board unit could do), bounded through the smoothed ones; snapshot: each epoch alone (weighted least squares), judged by the RAIM; auto (the default): smoothed (snapshot where a log is too short to measure its noise, saying why). Pseudoranges below 30 dB-Hz are left out of the trajectory (not of the snapshot RAIM). Recorded in the invoice (positioning, positioning_used).")]
Environment = Annotated[Literal[ENVIRONMENTS], typer.Option("--environment", help="Error model's environment: auto (urban where the residuals of the last 30 s exceed the nominal model 1.5-fold: C/N0-weighted urban σ there), open (the nominal model throughout) or urban (the urban σ throughout). Where a geo-object declares the environment of its road (geoobjects build --environment), the model level takes that one for the positions inside it that no residual measured — unless urban is given here.")]
PSat = Annotated[float, typer.Option("--p-sat", help="--raim ss: prior probability of a satellite fault (1e-15–0.5).", min=PROBABILITY_FLOOR, max=0.5)]
PConst = Annotated[float, typer.Option("--p-const", help="--raim ss: prior probability of a constellation-wide fault (1e-15–0.5).", min=PROBABILITY_FLOOR, max=0.5)]
Hal = Annotated[float, typer.Option("--hal", help="Horizontal alert limit, m (0–10 000).", min=0.0, max=10_000.0)]
PMd = Annotated[float, typer.Option("--p-md", help="Probability of missed detection (1e-15–0.5).", min=PROBABILITY_FLOOR, max=0.5)]
PFa = Annotated[float, typer.Option("--p-fa", help="Probability of false alarm (1e-15–0.5): classic RAIM's design value; under ETC an alarm at a higher per-epoch P_FA reads probable_false_alarm.", min=PROBABILITY_FLOOR, max=0.5)]
IntegritySources = Annotated[
    Literal[INTEGRITY_LEVELS],
    typer.Option("--integrity-sources", help="Which integrity sources may validate a position: residual (GRS residuals, "
                 "pseudoranges), receiver (and the receiver's own RAIM, GBS), covariance (and the GST error ellipse), or "
                 "auto: the strictest the log supports (decided at its first epoch with any source). A fault or an "
                 "exceeded bound from any source always counts."),
]
Fde = Annotated[bool, typer.Option("--fde", help="Fault detection and exclusion: drop one satellite when exactly one subset passes.")]
SigmaModel = Annotated[
    Literal[SIGMA_MODELS],
    typer.Option("--sigma-model", help="Pseudorange error model: nominal (thesis; alias urban, rural), constant (--sigma), input (σ from the log)."),
]
Sigma = Annotated[float, typer.Option("--sigma", help="σ of every pseudorange for --sigma-model constant, m (0.01–1 000).", min=0.01, max=1_000.0)]
Tc = Annotated[float, typer.Option("--tc", help="Correlation time: independent positions are at least this far apart, s (0.1–86 400).", min=0.1, max=86_400.0)]
NTh = Annotated[int, typer.Option("--n-th", help="Charge when at least this many valid independent positions fell inside (1–10 000).", min=1, max=10_000)]
Iono = Annotated[Literal[IONO_MODELS], typer.Option("--iono", help="Nominal model ionosphere: single (single frequency), sbas, iono-free.")]
MaxBad = Annotated[
    Optional[int],
    typer.Option("--max-bad", help="Exit 3 (partial) when more than this many lines were skipped; outputs are still written.", min=0),
]


TariffVehicleClass = Annotated[str, typer.Option("--vehicle-class", help="Vehicle class: car, van, truck, bus or motorcycle (the tariff's fees and the top speed of the findings).")]
VehicleAttr = Annotated[
    Optional[list[str]],
    typer.Option("--vehicle-attr", metavar="KEY=VALUE", help="A vehicle attribute a per-km tariff rates by (repeatable): weight_class=over-18t, axles=5+, euro_class=euro6, co2_class=1 (the tariff's [vehicle] names them)."),
]


def vehicle_attrs(items: list[str] | None) -> dict[str, str] | None:
    """``KEY=VALUE`` options → {key: value} (None when none was given); a UsageError for a malformed or repeated one."""
    from tollcli.errors import UsageError

    if not items:
        return None
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise UsageError(f"--vehicle-attr {item!r}: give KEY=VALUE, e.g. euro_class=euro6")
        if key in out and out[key] != value:
            raise UsageError(f"--vehicle-attr {key}: given twice ({out[key]!r} and {value!r})")
        out[key] = value
    return dict(sorted(out.items()))
