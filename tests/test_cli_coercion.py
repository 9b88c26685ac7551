"""Option values typed without pydantic (:mod:`tollcli.cli.coercion`) are Typer's own: for every option of every
command and a list of awkward values, the same value of the same type, or the same error message."""

from __future__ import annotations

import math

import click
import pytest
import typer
from typer._coercion import build_runtime_param
from typer._param_types import choice_coercion_annotation

from tollcli.cli import coercion
from tollcli.cli.app import build_app

AWKWARD = ["", " ", "0", "-0", "+5", "007", "1_000", " 5", "5 ", "1e3", "1E-3", "1.", ".5", "1.5", "-2.25", "0.0", "-1",
           "inf", "-inf", "nan", "NaN", "0x10", "\u0661\u0662", "1e400", "9" * 30, "abc", "AUTO", "auto", "2026-01-01",
           "1,5", "½", "true", "False", 5, 5.0, -3, True, 2.5, ("a", "b"), ["x"], (), ("a", 1), b"bytes"]  # fmt: skip


def _params():
    command = typer.main.get_command(build_app())
    stack, found = [(command, click.Context(command))], []
    while stack:
        cmd, ctx = stack.pop()
        for name, sub in getattr(cmd, "commands", {}).items():
            stack.append((sub, click.Context(sub, parent=ctx, info_name=name)))
        found += [(cmd, ctx, p) for p in cmd.params if hasattr(p, "type_descriptor")]
    return found


PARAMS = _params()


def _outcome(runtime, value, param, ctx):
    try:
        v = runtime._coerce_value(value, param=param, ctx=ctx)
    except Exception as exc:  # noqa: BLE001 - the kind and the words are what is compared
        return ("error", type(exc).__name__, str(exc))
    return ("value", type(v).__name__, "nan" if isinstance(v, float) and math.isnan(v) else repr(v))


def test_every_option_of_every_command_is_covered():
    kinds = {coercion._kind(p.type_descriptor) for _, _, p in PARAMS}
    assert len(PARAMS) > 200
    assert {"str", "bool", "float", "int", "list[str]", "choice", "other"} <= kinds


@pytest.mark.parametrize("index", range(0, len(PARAMS)))
def test_the_same_value_or_the_same_message_as_typer(index):
    cmd, ctx, param = PARAMS[index]
    descriptor = param.type_descriptor
    plain = coercion._Plain(descriptor.parameter_info, descriptor.annotation, coercion._kind(descriptor), descriptor)
    values = list(AWKWARD)
    choices = choice_coercion_annotation(descriptor.annotation, descriptor.parameter_info)
    if choices:
        values += [str(c) for c in choices[0]] + [str(c).upper() for c in choices[0]]
    info = descriptor.parameter_info
    values += [str(b + d) for b in (info.min, info.max) if b is not None for d in (-1, -1e-9, 0, 1e-9, 1)]
    for value in values:
        assert _outcome(plain, value, param, ctx) == _outcome(build_runtime_param(descriptor), value, param, ctx), (cmd.name, param.name, value)


def test_plain_values_are_typed_without_asking_typer():
    _, ctx, param = next(t for t in PARAMS if coercion._kind(t[2].type_descriptor) == "float" and t[2].type_descriptor.parameter_info.min is None)
    info, ann = param.type_descriptor.parameter_info, param.type_descriptor.annotation
    assert coercion._plain("float", "-2.5e1", info, ann, ctx) == -25.0
    assert coercion._plain("float", "1_0", info, ann, ctx) is coercion._TYPER
    assert coercion._plain("int", "12", info, int, ctx) == 12
    assert coercion._plain("other", "x", info, ann, ctx) is coercion._TYPER


def test_installed_on_this_typer():
    assert coercion.install()
    assert coercion.install()  # twice: once


def test_a_typer_whose_parameters_are_not_as_expected_keeps_its_own_coercion(monkeypatch):
    def unexpected(descriptor):
        raise AttributeError("parameter_info has no min")

    assert coercion.install()
    param = next(p for _, _, p in _params() if coercion._kind(p.type_descriptor) == "float")
    monkeypatch.setattr(coercion, "_kind", unexpected)
    runtime = param.get_runtime_param()
    assert not isinstance(runtime, coercion._Plain)
    assert runtime.coerce("2.5", param=param, ctx=None) == 2.5
