"""The invoice's canonical JSON text, written faster than ``json.dumps`` with an indent.

``canonical_json(obj)`` is byte for byte ``json.dumps(obj, indent=2, sort_keys=True,
ensure_ascii=False, allow_nan=False)`` (tested on invoices and on random documents): a NaN or an infinity
is refused (ValueError), never written as the ``NaN``/``Infinity`` that JSON readers reject. The standard
library encodes an indented document with its pure-Python generator encoder; this
writer joins strings directly and encodes strings with the standard library's C
string encoder. Anything it does not know (a non-string key, an object of another
type) is handed to ``json.dumps``, which encodes it or raises as usual.
"""

from __future__ import annotations

import json
from json.encoder import encode_basestring  # the C encoder where available

_INDENT = "  "
_CONSTANTS = {True: "true", False: "false"}


class _Unusual(Exception):
    """A value this writer leaves to json.dumps."""


def _float(x: float) -> str:
    if x != x or x in (_INF, -_INF):  # NaN and infinities are not JSON: an invoice holding one is refused
        raise ValueError(f"Out of range float values are not JSON compliant: {x!r}")
    return float.__repr__(x)


_INF = float("inf")


def _value(o, newline: str) -> str:
    """``o`` encoded, its nested lines starting with ``newline`` (a line feed and the indent of ``o``'s level)."""
    t = type(o)
    if t is str:
        return encode_basestring(o)
    if t is float:
        return _float(o)
    if t is int:
        return int.__repr__(o)
    if o is None:
        return "null"
    if t is bool:
        return _CONSTANTS[o]
    inner = newline + _INDENT
    if t is not dict and t is not list and t is not tuple:  # subclasses, in json's order (numpy scalars among them)
        if isinstance(o, str):
            return encode_basestring(o)
        if isinstance(o, int):
            return _CONSTANTS[o] if isinstance(o, bool) else int.__repr__(o)
        if isinstance(o, float):
            return _float(o)
        if isinstance(o, (list, tuple)):
            t = list
        elif isinstance(o, dict):
            t = dict
    if t is dict:
        return _dict(o, inner, newline)
    if t is list or t is tuple:
        if not o:
            return "[]"
        return "[" + inner + ("," + inner).join([_item(v, inner) for v in o]) + newline + "]"
    raise _Unusual


#: encoders of the exact scalar types (the common case, without a call to _value)
_SCALARS = {str: encode_basestring, float: _float, int: int.__repr__}
_KEYS: dict[str, str] = {}  # encoded keys (an invoice repeats a few dozen)


def _item(v, inner: str) -> str:
    f = _SCALARS.get(type(v))
    return f(v) if f is not None else _value(v, inner)


def _dict(o: dict, inner: str, newline: str) -> str:
    if not o:
        return "{}"
    try:
        items = sorted(o.items())
    except TypeError:
        raise _Unusual from None
    parts = []
    for k, v in items:
        if type(k) is not str:
            raise _Unusual
        key = _KEYS.get(k)
        if key is None:
            key = encode_basestring(k) + ": "
            if len(_KEYS) < 4096:
                _KEYS[k] = key
        f = _SCALARS.get(type(v))
        parts.append(key + (f(v) if f is not None else _value(v, inner)))
    return "{" + inner + ("," + inner).join(parts) + newline + "}"


def canonical_json(obj) -> str:
    """``json.dumps(obj, indent=2, sort_keys=True, ensure_ascii=False, allow_nan=False)``, the same text, faster."""
    try:
        return _value(obj, "\n")
    except (_Unusual, RecursionError):
        return json.dumps(obj, indent=2, sort_keys=True, ensure_ascii=False, allow_nan=False)
