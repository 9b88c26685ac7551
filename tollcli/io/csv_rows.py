"""A chunk of columns → its CSV rows in one compiled pass (``_csv_kernel.c``): the bytes Python's ``csv`` module
writes for the cells :func:`tollcli.io.writers._csv_cells` makes (:func:`csv_text`), or that pandas' ``to_csv`` writes
for a DataFrame the way :class:`~tollcli.io.writers.TableWriter` calls it (:func:`frame_csv_text`); those stay the
reference and the fallback.

Floats are formatted ``%.15g`` in C (NaN empty), integers in decimal, booleans ``True``/``False``; times and text
come as cells made here. A chunk the kernel cannot write exactly as the ``csv`` module would — a text cell it
would quote (a comma, a quote, a line break), a single column, an unsigned 64-bit integer, a column of another
kind — and every chunk where the kernel was not built is left to the reference (:func:`csv_text` gives None).
``tests/test_csv_rows.py`` holds the two to the same bytes.
"""

from __future__ import annotations

import numpy as np

from tollcli.io.columns import Coded, Columns, is_text, is_time
from tollcli.kernels import compiled_module

compiled = compiled_module("tollcli.io._csv_kernel")

#: characters that make the csv module quote a cell (QUOTE_MINIMAL, ``,`` delimiter, ``"`` quote, ``\n`` lines)
_QUOTED = (",", '"', "\n", "\r")


def csv_text(table: Columns, iso_ms) -> bytes | None:
    """The CSV rows of ``table`` (no header; each row ended by ``\\n``; UTF-8), or None: left to the reference.

    ``iso_ms``: datetime64 values → their ISO cells (the writer's own, so that both paths write the same times)."""
    if compiled is None or len(table.columns) < 2:
        return None
    kinds, columns = [], []
    for name, held in table.items():
        if isinstance(held, Coded) and (np.asarray(held.codes) >= 0).all():  # few distinct texts: each written once
            names = list(held.names)
            if not _plain(names):
                return None
            kinds.append("c")
            columns.append(_coded_cells(np.asarray(held.codes, np.int64), names))
            continue
        values = table[name]
        if is_time(values):
            kinds.append("c")
            columns.append(_time_cells(values, iso_ms))
        elif is_text(values):
            texts = [v if isinstance(v, str) else "" for v in values.tolist()]
            if not _plain(set(texts)):
                return None
            kinds.append("c")
            columns.append(_cells(texts))
        elif (number := _number_column(values, any_float=True)) is not None:
            kinds.append(number[0])
            columns.append(number[1])
        else:
            return None
    return compiled.rows("".join(kinds).encode(), tuple(columns), len(table))


def frame_csv_text(df) -> bytes | None:
    """The CSV rows pandas' ``to_csv(index=False, header=False, lineterminator="\\n", float_format="%.15g")`` writes
    for ``df`` (its UTC times already ISO text; UTF-8), or None: left to pandas. Columns of float64, of numpy integers or
    booleans, and of text (pandas' string dtypes, or objects that are all text or missing) are written here; a
    column of another kind (nullable integers, categories, naive times, other objects) leaves the chunk to pandas."""
    import pandas as pd

    if compiled is None or df.shape[1] < 2 or not all(isinstance(c, str) for c in df.columns) or not df.columns.is_unique:
        return None
    kinds, columns = [], []
    for name in df.columns:
        col = df[name]
        if isinstance(col.dtype, np.dtype) and (number := _number_column(col.to_numpy(), any_float=False)) is not None:
            kinds.append(number[0])
            columns.append(number[1])
        elif isinstance(col.dtype, pd.StringDtype) or col.dtype == object:
            codes, uniques = pd.factorize(col, use_na_sentinel=True)  # missing (None, NaN, NA): -1
            names = list(uniques)
            if not _plain(names):
                return None  # a value not text (pandas writes its str()), or a text the csv module would quote
            kinds.append("c")
            columns.append(_coded_cells(np.asarray(codes, np.int64), names))
        else:
            return None
    return compiled.rows("".join(kinds).encode(), tuple(columns), len(df))


def _number_column(values: np.ndarray, any_float: bool) -> tuple[str, np.ndarray] | None:
    """(the kernel's kind, the array it reads) of a numpy column of floats (float64 only unless ``any_float``: a
    narrower float converts exactly, as the csv module sees it), integers (not unsigned 64-bit) or booleans; None for
    any other."""
    kind, dtype = values.dtype.kind, values.dtype
    if kind == "f" and (any_float or dtype == np.float64):
        return "f", np.ascontiguousarray(values, dtype=np.float64)
    if kind == "b":
        return "b", np.ascontiguousarray(values, dtype=np.uint8)
    if kind == "i" or (kind == "u" and dtype.itemsize < 8):
        return "i", np.ascontiguousarray(values, dtype=np.int64)
    return None


def _plain(texts) -> bool:
    """Whether every one of ``texts`` is text the csv module writes as it is (no quoting)."""
    return all(isinstance(t, str) for t in texts) and not any(q in t for t in texts for q in _QUOTED)


def _time_cells(values: np.ndarray, iso_ms) -> tuple[bytes, np.ndarray]:
    """:func:`_cells` of datetime64 values, each run of one time (a satellite table's epoch) formatted once."""
    ms = values.astype("datetime64[ms]")
    if ms.size == 0:
        return b"", np.zeros(1, np.int64)
    change = np.empty(ms.size, bool)
    change[0] = True
    np.not_equal(ms.view(np.int64)[1:], ms.view(np.int64)[:-1], out=change[1:])
    return _coded_cells(np.cumsum(change) - 1, iso_ms(ms[change]))


def _coded_cells(codes: np.ndarray, names: list[str]) -> tuple[bytes, np.ndarray]:
    """:func:`_cells` of ``names[codes]`` (-1: empty), each name encoded once."""
    encoded = np.array([t.encode("utf-8") for t in names] + [b""], dtype=object)
    lengths = np.array([len(b) for b in encoded], np.int64)
    offsets = np.zeros(codes.size + 1, np.int64)
    np.cumsum(lengths[codes], out=offsets[1:])
    return b"".join(encoded[codes].tolist()), offsets


def _cells(texts: list[str]) -> tuple[bytes, np.ndarray]:
    """Cells → (their UTF-8 bytes end to end, int64 offsets: cell i is ``data[offsets[i]:offsets[i + 1]]``)."""
    encoded = [t.encode("utf-8") for t in texts]
    offsets = np.zeros(len(encoded) + 1, np.int64)
    np.cumsum([len(b) for b in encoded], out=offsets[1:])
    return b"".join(encoded), offsets
