"""Option values turned into their types without building a pydantic model per option.

Typer 0.29 coerces every option's value through a pydantic ``TypeAdapter`` it builds on first use: importing
pydantic and building the adapters of one command's options takes about 0.13 s, before a byte of the log is read
(a third of ``tollcli epochs`` on a short log). :func:`install` gives each option of the plain kinds tollcli uses — a
string, a list of strings, a number written as plain decimals (with its ``min``/``max``), a choice among literals —
a coercion that needs no pydantic, and that hands any other value (``1_000``, `` 5``, ``inf``, a number out of range,
a choice not offered) to Typer's own adapter, built then: the same value, or the same message, as Typer alone
(tested over every option of every command and a list of awkward values). An option of another kind (a date) is not
coerced when it is not given, and goes to Typer's adapter when it is. Where Typer's internals are not what this
expects, nothing is installed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, get_args, get_origin

try:  # Typer's runtime coercion (0.29): where it is not there, install() does nothing
    from typer._coercion import RuntimeParam, build_runtime_param
    from typer._param_types import choice_coercion_annotation, coerce_cli_choice
    from typer.core import _TyperParameter
except ImportError:  # pragma: no cover - another Typer
    RuntimeParam = None

_INT = re.compile(r"[+-]?[0-9]+")
_FLOAT = re.compile(r"[+-]?[0-9]+(\.[0-9]+)?([eE][+-]?[0-9]+)?")


def install() -> bool:
    """Give every Typer option, when its value is first coerced, the coercion of this module instead of Typer's
    (options made while parsing, as ``--help``, too). Returns whether it is installed (False: another Typer)."""
    if RuntimeParam is None:
        return False
    if getattr(_TyperParameter.get_runtime_param, "tollcli_plain", False):
        return True

    def get_runtime_param(param):
        if param._runtime_param is None:
            descriptor = param.type_descriptor
            try:
                param._runtime_param = _Plain(descriptor.parameter_info, descriptor.annotation, _kind(descriptor), descriptor)
            except (AttributeError, TypeError):  # a Typer whose parameters are not what this expects: its own coercion
                param._runtime_param = build_runtime_param(descriptor)
        return param._runtime_param

    get_runtime_param.tollcli_plain = True
    _TyperParameter.get_runtime_param = get_runtime_param
    return True


def _kind(descriptor) -> str:
    """What a parameter is, of the kinds coerced here ("other": every value it is given goes to Typer)."""
    info, annotation = descriptor.parameter_info, descriptor.annotation
    if descriptor.file_annotation is not None or info.parser is not None or getattr(info, "click_type", None) is not None:
        return "other"
    if annotation is bool:
        return "bool"
    if annotation is str:
        return "str"
    if get_origin(annotation) is list and get_args(annotation) == (str,):
        return "list[str]"
    if annotation in (int, float) and not info.clamp:
        return annotation.__name__
    if choice_coercion_annotation(annotation, info) is not None:
        return "choice"
    return "other"


if RuntimeParam is not None:

    @dataclass(frozen=True)
    class _Plain(RuntimeParam):
        """A plain option's coercion; anything it is not sure of goes to Typer's adapter."""

        kind: str
        descriptor: Any

        def _coerce_value(self, value: Any, param, ctx) -> Any:
            done = _plain(self.kind, value, self.parameter_info, self.annotation, ctx)
            if done is not _TYPER:
                return done
            return build_runtime_param(self.descriptor)._coerce_value(value, param=param, ctx=ctx)


_TYPER = object()  # "ask Typer"


def _plain(kind: str, value: Any, info, annotation, ctx) -> Any:
    """The coerced value, or _TYPER where Typer's adapter must decide (or word the error)."""
    if kind == "other":
        return _TYPER
    if kind in ("str", "bool"):
        return value if type(value) is annotation else _TYPER
    if kind == "list[str]":
        return list(value) if type(value) in (list, tuple) and all(type(v) is str for v in value) else _TYPER
    if kind == "choice":
        if type(value) is not str:
            return _TYPER
        choices, case_sensitive = choice_coercion_annotation(annotation, info)
        try:
            return coerce_cli_choice(value, choices=choices, case_sensitive=case_sensitive, ctx=ctx)
        except ValueError:
            return _TYPER
    # int or float: a plain decimal string, or a number of the type already (a default)
    if type(value) is str:
        if not (_INT if kind == "int" else _FLOAT).fullmatch(value):
            return _TYPER
        number = int(value) if kind == "int" else float(value)
    elif type(value) is annotation:
        number = value
    else:
        return _TYPER
    if (info.min is not None and number < info.min) or (info.max is not None and number > info.max):
        return _TYPER
    return number
