"""Man pages generated from the Typer app, so they never drift from ``--help``.

    python -m tollcli.cli.manpage man/      # writes tollcli.1 and tollcli-<command>.1

A test checks that the committed pages in ``man/`` are what this produces.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from tollcli import __version__

EXIT_STATUS = (
    ("0", "success"),
    ("1", "data error: the input is unusable (empty, not NMEA, no epoch, a bad geo-object or tariff file), "
          "a bad line under --strict, or verify found a difference"),
    ("2", "usage error: bad option, missing file, a directory where a file was expected, unknown output format"),
    ("3", "partial: outputs were written but more lines were skipped than --max-bad allows"),
    ("4", "system error: a file could not be written or read (read-only folder, disk full, permissions)"),
    ("5", "internal error: a defect of tollcli, named in one line (please report it; TOLLCLI_DEBUG=1 shows the traceback)"),
    ("6", "some failed: batch wrote the outputs of every log it could, but some logs failed (failed/ says why; 4 when the system refused their files)"),
)  # fmt: skip
FILES = (
    ("geoobjects/*.geojson", "geo-objects: constant-HAL buffer polygons with id, hal_m, road_class (tollcli geoobjects build)"),
    ("geoobjects/*.toml", "tariffs: fees per geo-object or road class and vehicle class, time-of-day bands"),
    ("samples/", "bundled drive logs and the script that made them"),
    ("~/.cache/tollcli/", "compiled geo-object files (by SHA-256 of the GeoJSON) and RAIM threshold tables; "
                          "safe to delete, rebuilt when missing"),
)
ENVIRONMENT = (
    ("TOLLCLI_CACHE_DIR", "where the cache goes (default $XDG_CACHE_HOME/tollcli or ~/.cache/tollcli); "
                          "'off' turns it off. Results never depend on it: every cached file is named by all its inputs "
                          "and checked against the SHA-256 written with it before use; a folder others can write is not "
                          "used (a sticky shared one holds a private tollcli-UID folder per user); verify reads no cache"),
    ("TOLLCLI_READ_AHEAD", "'0': process, integrity, locate and findings read a receiver log on one thread (by default the "
                           "next chunk is read on a second thread while the current one is checked). The outputs are the same "
                           "byte for byte either way. batch's workers do not read ahead when there are as many as cores ('1' makes them)"),
    ("TOLLCLI_KERNELS", "'numpy': the NMEA reader and the trajectory filter use their numpy versions instead of the compiled "
                        "ones (the same tables and invoices, slower; what an install without a C compiler gets)"),
    ("NO_COLOR", "no colours in the tables shown on a terminal"),
)


_DRIVE = "samples/sim/urban-fault/drive.nmea"
_GEO = "--geo geoobjects/example-geoobjects.geojson"
EXAMPLES = {
    "tollcli": ["tollcli process samples/straight-drive.nmea " + _GEO + " --tariff geoobjects/example-tariff.toml -o invoice.json",
                "tollcli audit invoice.json --truth samples/sim/urban-fault/truth.csv " + _GEO],
    "tollcli-process": ["tollcli process " + _DRIVE + " " + _GEO + " --tariff geoobjects/example-tariff.toml -o invoice.json",
                        "zcat day.nmea.gz | tollcli process - " + _GEO + " --tariff geoobjects/example-tariff.toml --raim classic -o -",
                        "tollcli process " + _DRIVE + " " + _GEO + " --tariff geoobjects/example-tariff.toml -f csv -o - --config settings.toml",
                        "tollcli process other.nmea " + _GEO + " --tariff geoobjects/example-tariff.toml --config invoice.json -o other.json"],
    "tollcli-info": ["tollcli info samples/straight-drive.nmea", "tollcli info drive.pos --json",
                     "tollcli info geoobjects/example-geoobjects.geojson"],
    "tollcli-audit": ["tollcli audit invoice.json --truth samples/sim/urban-fault/truth.csv " + _GEO,
                      "tollcli audit runs/ --tariff geoobjects/example-tariff.toml " + _GEO + " -o risk.json",
                      "tollcli audit --epochs integrity.csv --truth samples/sim/urban-fault/truth.csv"],
    "tollcli-verify": ["tollcli verify invoice.json"],
    "tollcli-epochs": ["tollcli epochs samples/straight-drive.nmea -o epochs.parquet --satellites sats.csv",
                       "cat log.nmea | tollcli epochs - -o - | head"],
    "tollcli-integrity": ["tollcli integrity " + _DRIVE + " --raim etc --hal 40 -o integrity.csv",
                          "tollcli integrity derived.csv --input-format gsdc-derived --sigma-model input --fde -o integrity.parquet",
                          "tollcli integrity drive.pos --config settings.toml -f parquet -o - > integrity.parquet"],
    "tollcli-design": ["tollcli design --dof 4 --p-fa 5e-3 --p-md 5e-5 --json", "tollcli design --dof 1 --p-md 5e-5 --hal-over-slope 7"],
    "tollcli-simulate": ["tollcli simulate --route geoobjects/example-roads.geojson --via A9-N1,A9-N2 " + _GEO + " --env urban --seed 1 -o drive/",
                         "tollcli simulate --env rural --duration 3600 --fault-bias 60 --fault-prob 0.1 --seed 7 -o faulty/"],
    "tollcli-locate": ["tollcli locate trucks/*.nmea.gz -o where.csv", "tollcli locate TRK-042.nmea --at 2026-03-02T08:01:00 --json -o -"],
    "tollcli-findings": ["tollcli findings " + _DRIVE + " " + _GEO + " --vehicle-class truck -o findings.json",
                         "tollcli findings " + _DRIVE + " " + _GEO + " -f geojson -o findings.geojson --json"],
    "tollcli-enforce": ["tollcli enforce trip.nmea --reads reads.csv --gantries gantries.geojson --tag TAG-1 -o roadside.json"],
    "tollcli-plot": ["tollcli plot invoice.json --truth samples/sim/urban-fault/truth.csv -o figures/",
                     "tollcli plot invoice.json -f svg -o figures/ --json"],
    "tollcli-report": ["tollcli report invoice.json --truth samples/sim/urban-fault/truth.csv -o report.html"],
    "tollcli-geoobjects": ["tollcli geoobjects build geoobjects/example-roads.geojson -o geo.geojson"],
    "tollcli-geoobjects-build": ["tollcli geoobjects build geoobjects/example-roads.geojson -o geo.geojson",
                                 "tollcli geoobjects build map.osm.pbf --tolled highway=motorway,trunk --hal motorway=40-50 --hal 25 -o geo.geojson",
                                 "tollcli geoobjects build roads.gpkg --hal 25 --json -o geo.geojson"],
    "tollcli-geoobjects-info": ["tollcli geoobjects info geoobjects/example-geoobjects.geojson",
                                "tollcli geoobjects info geo.geojson --min-hal 25 --json"],
    "tollcli-geoobjects-check": ["tollcli geoobjects check geoobjects/example-geoobjects.geojson --json"],
}  # fmt: skip


def _esc(text: str) -> str:
    return (text or "").replace("\\", "\\\\").replace("-", "\\-").replace("\n.", "\n\\&.").replace("'", "\\(aq")


def _param(prm) -> str:
    if type(prm).__name__.endswith("Argument"):
        return f".TP\n\\fI{_esc((prm.metavar or prm.name).upper().strip('{}'))}\\fR\n{_esc(prm.help or '')}\n"
    names = ", ".join(f"\\fB{_esc(o)}\\fR" for o in [*prm.opts, *getattr(prm, "secondary_opts", [])])
    default = "" if prm.is_flag or prm.default in (None, "", ()) or prm.required else f" (default: {_esc(str(prm.default))})"
    return f".TP\n{names}\n{_esc(prm.help or '')}{default}\n"


def _page(name: str, cmd, summary: str, subcommands: list[tuple[str, str]] | None = None) -> str:
    help_text = (cmd.help or "").strip()
    arguments = [p for p in cmd.params if type(p).__name__.endswith("Argument")]
    usage = " ".join(["[OPTIONS]"] + [(p.metavar or p.name).upper().strip("{}") for p in arguments])
    if hasattr(cmd, "commands"):
        usage += " COMMAND [ARGS]..."
    out = [f'.TH "{name.upper()}" "1" "" "tollcli {__version__}" "User Commands"',
           ".SH NAME", f"{_esc(name)} \\- {_esc(summary)}",
           ".SH SYNOPSIS", f"\\fB{_esc(name.replace('-', ' '))}\\fR {_esc(usage)}",
           ".SH DESCRIPTION", _esc(help_text).replace("\n\n", "\n.PP\n")]  # fmt: skip
    if subcommands:
        out.append(".SH COMMANDS")
        for sub, text in subcommands:
            out += [".TP", f"\\fB{_esc(sub)}\\fR", _esc(text)]
    params = [p for p in cmd.params if getattr(p, "name", "") not in ("install_completion", "show_completion") and not getattr(p, "hidden", False)]
    if params:
        out.append(".SH OPTIONS")
        out += [_param(p).rstrip("\n") for p in params]
    if EXAMPLES.get(name):
        out.append(".SH EXAMPLES")
        for example in EXAMPLES[name]:
            out += [".PP", ".nf", _esc(example), ".fi"]
    out.append(".SH EXIT STATUS")
    for code, meaning in EXIT_STATUS:
        out += [".TP", f"\\fB{code}\\fR", _esc(meaning)]
    out.append(".SH ENVIRONMENT")
    for name_, meaning in ENVIRONMENT:
        out += [".TP", f"\\fB{name_}\\fR", _esc(meaning)]
    out.append(".SH FILES")
    for path, meaning in FILES:
        out += [".TP", f"\\fI{_esc(path)}\\fR", _esc(meaning)]
    out += [".SH SEE ALSO", "\\fBtollcli\\fR(1), \\fBtollcli \\-\\-help\\fR", ""]
    return "\n".join(out)


def manpages() -> dict[str, str]:
    """File name → roff text for tollcli(1) and every sub-command."""
    from tollcli.cli.app import app

    root = typer.main.get_command(app)
    pages: dict[str, str] = {}
    listed = []

    def walk(prefix: str, group) -> None:
        for sub_name, sub in sorted(group.commands.items()):
            name = f"{prefix}-{sub_name}"
            summary = (sub.help or "").strip().splitlines()[0] if sub.help else sub_name
            if hasattr(sub, "commands"):
                walk(name, sub)
                subs = [(s, (c.help or "").strip().splitlines()[0]) for s, c in sorted(sub.commands.items())]
                pages[f"{name}.1"] = _page(name, sub, summary, subs)
            else:
                pages[f"{name}.1"] = _page(name, sub, summary)
            if prefix == "tollcli":
                listed.append((sub_name, summary))

    walk("tollcli", root)
    pages["tollcli.1"] = _page("tollcli", root, "GNSS road-user charging log processor", listed)
    return dict(sorted(pages.items()))


def write(folder: str) -> list[str]:
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in manpages().items():
        (out / name).write_text(text, encoding="utf-8")
    return list(manpages())


if __name__ == "__main__":
    print("\n".join(write(sys.argv[1] if len(sys.argv) > 1 else "man")))
