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
)  # fmt: skip
FILES = (
    ("geoobjects/*.geojson", "geo-objects: constant-HAL buffer polygons with id, hal_m, road_class (tollcli geoobjects build)"),
    ("geoobjects/*.toml", "tariffs: fees per geo-object or road class and vehicle class, time-of-day bands"),
    ("samples/", "bundled drive logs and the script that made them"),
)


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
    params = [p for p in cmd.params if getattr(p, "name", "") not in ("install_completion", "show_completion")]
    if params:
        out.append(".SH OPTIONS")
        out += [_param(p).rstrip("\n") for p in params]
    out.append(".SH EXIT STATUS")
    for code, meaning in EXIT_STATUS:
        out += [".TP", f"\\fB{code}\\fR", _esc(meaning)]
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
