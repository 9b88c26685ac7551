"""``--config FILE``: a command's options kept in a file (as RTKLIB's ``rnx2rtkp -k``), or an invoice's settings.

A settings file is TOML; its keys are the options' long names (``p-md`` or ``p_md``)::

    raim = "ss"
    p-md = 5e-5
    vehicle-attr = ["euro_class=euro6"]
    [integrity]          # keys for one command only (process, batch, integrity)
    hal = 50

A key that is an option of another of those commands but not of this one is passed over (one file serves
``process``, ``batch`` and ``integrity``); a key that is no option of any is an error. Options given on the
command line win over the file. An invoice (``.json``) gives its ``parameters``: a run with them is the run
the invoice records, so ``tollcli process LOG --geo G --tariff T --config invoice.json`` writes the same
invoice again.
"""

from __future__ import annotations

import datetime as dt
import json
import tomllib
from typing import Annotated, Optional

import click
import typer

from tollcli.errors import UsageError

#: the commands a settings file serves
COMMANDS = ("process", "batch", "integrity")
#: an invoice's parameters that are not options: what the run derived (recorded for the reader), not what it was given
DERIVED = frozenset({"valid_statuses", "policy_used", "integrity_sources_used", "continued"})
#: an invoice's parameter name → the option's name, where the two differ
PARAMETER_OPTION = {"sigma_m": "sigma", "tc_s": "tc", "vehicle_attrs": "vehicle_attr"}
#: options a settings file cannot hold: the files a run reads and writes, its output format, how it is executed and
#: what only prints. They come from the command line alone: a settings file may be an invoice from anyone, and must
#: not make a run read a network or tariff, or write a file, that the user did not name
NOT_SETTINGS = frozenset({"config", "help", "quiet", "as_json", "log", "inputs", "output", "out_fmt", "fmt", "geo", "tariff",
                          "nav", "roads", "osnma_merkle", "osnma_public_key", "fleet", "workers", "scheduler", "force"})  # fmt: skip


def _known_elsewhere() -> set[str]:
    """Every option name of the commands a settings file serves."""
    import importlib

    from tollcli.cli.app import COMMANDS as ALL

    names: set[str] = set()
    for command in COMMANDS:
        module, attr = ALL[command]
        fn = getattr(importlib.import_module(module), attr)
        names.update(p for p in fn.__annotations__ if p != "return")
    return names


def read_settings(path: str) -> dict:
    """The settings in ``path``: a TOML file (its tables kept), or an invoice's ``parameters``; a UsageError else."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise UsageError(f"--config {path}: {exc.strerror or exc}") from None
    if path.lower().endswith(".json"):
        try:
            doc = json.loads(raw)
        except (UnicodeDecodeError, ValueError) as exc:  # (ValueError: not JSON, or an integer of over 4 300 digits)
            raise UsageError(f"--config {path}: not JSON ({' '.join(str(exc).split())[:200]})") from None
        except RecursionError:
            raise UsageError(f"--config {path}: not JSON (nested too deeply)") from None
        params = doc.get("parameters") if isinstance(doc, dict) else None
        if not isinstance(params, dict):
            raise UsageError(f"--config {path}: a JSON settings file is an invoice, with its parameters")
        return {PARAMETER_OPTION.get(k, k): _option_value(v) for k, v in params.items() if k not in DERIVED and v is not None}
    try:
        doc = tomllib.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError) as exc:  # (tomllib.TOMLDecodeError, or an integer of over 4 300 digits)
        raise UsageError(f"--config {path}: not TOML ({' '.join(str(exc).split())[:200]})") from None
    except RecursionError:
        raise UsageError(f"--config {path}: not TOML (nested too deeply)") from None
    return doc


def _option_value(value):
    """An invoice's parameter as its option takes it (attributes as KEY=VALUE items)."""
    if isinstance(value, dict):
        return [f"{k}={v}" for k, v in sorted(value.items())]
    return value


def settings_for(command: str, doc: dict, path: str, options: set[str]) -> dict:
    """The default map of ``command`` from a settings document: its top-level keys and its own table."""
    known = _known_elsewhere()
    out: dict = {}
    merged = {k: v for k, v in doc.items() if not (k in COMMANDS and isinstance(v, dict))}
    merged.update(doc.get(command) or {})
    for key, value in merged.items():
        name = key.replace("-", "_")
        name = "out_fmt" if name == "format" else name  # -f/--format's parameter
        if name in NOT_SETTINGS:
            raise UsageError(f"--config {path}: {key!r} is not a setting (files, outputs and how a run is executed are "
                             "given on the command line)")  # fmt: skip
        if name in options:
            if isinstance(value, (dt.date, dt.time)):  # a TOML date (date = 2026-03-02, unquoted): as the option writes it
                value = value.isoformat(timespec="seconds") if isinstance(value, dt.datetime) else value.isoformat()
            out[name] = value
        elif name not in known:
            raise UsageError(f"--config {path}: {key!r} is no option of {', '.join(COMMANDS)}")
    return out


def _takes_a_date(param) -> bool:
    """Whether an option's value is a date or time (typer's bare type, or click's DateTime)."""
    bare = getattr(param, "bare_type", None)
    if callable(bare):
        return "date" in str(bare()) or "time" in str(bare())
    return isinstance(getattr(param, "type", None), click.DateTime)


def _check_type(param, value, path: str) -> None:
    """UsageError unless a settings value has its option's type: a boolean is true or false (never "yes"), a number a
    number (never text or a boolean), anything else text (or a list of texts for an option given several times)."""
    bare = param.bare_type() if callable(getattr(param, "bare_type", None)) else getattr(param, "type", None)
    name = bare if isinstance(bare, str) else getattr(bare, "__name__", "")  # (typer gives the annotation, or its text)
    if name == "bool" or isinstance(bare, click.types.BoolParamType) or getattr(param, "is_flag", False):
        ok, want = isinstance(value, bool), "true or false"
    elif name == "int" or isinstance(bare, click.types.IntParamType):
        ok, want = isinstance(value, int) and not isinstance(value, bool), "a whole number"
    elif name == "float" or isinstance(bare, click.types.FloatParamType):
        ok, want = isinstance(value, (int, float)) and not isinstance(value, bool), "a number"
    elif getattr(param, "multiple", False):
        ok, want = isinstance(value, list) and all(isinstance(v, str) for v in value), "a list of texts"
    else:
        ok, want = isinstance(value, str), "a text"
    if not ok:
        raise UsageError(f"--config {path}: {param.name} = {str(value)[:40]!r} is not {want}")


def _load(ctx: typer.Context, param: typer.CallbackParam, value: str | None) -> str | None:
    if not value:
        return value
    options = {p.name for p in ctx.command.params if p.param_type_name == "option"}
    defaults = settings_for(ctx.info_name or "", read_settings(value), value, options)
    repeatable = {p.name for p in ctx.command.params if p.param_type_name == "option" and getattr(p, "multiple", False)}
    defaults = {k: [v] if k in repeatable and isinstance(v, str) else v for k, v in defaults.items()}  # nav = "f" as ["f"]
    for p in ctx.command.params:  # a date or time option takes text (a TOML date became text above); a number is none
        if p.name in defaults and _takes_a_date(p) and not isinstance(defaults[p.name], str):
            raise UsageError(f"--config {value}: {p.name} = {str(defaults[p.name])[:40]!r} is not a date (write it as 2026-03-02)")
        if p.name in defaults:
            _check_type(p, defaults[p.name], value)
    ctx.default_map = {**(ctx.default_map or {}), **defaults}
    return value


Config = Annotated[
    Optional[str],
    typer.Option("--config", metavar="FILE", is_eager=True, callback=_load, show_default=False,
                 help="Settings: a TOML file of options by their long names ([process], [batch], [integrity] tables "
                      "for one command), or an invoice whose parameters to run with. Options given here win."),
]
