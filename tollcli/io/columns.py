"""A table as named numpy arrays — what the readers give before anything needs pandas.

>>> t = Columns({"epoch": np.arange(2), "lat_deg": np.array([48.1, np.nan])})
>>> len(t), t.columns, t["lat_deg"][0]
(2, ['epoch', 'lat_deg'], 48.1)

Each column is one numpy array, all of one length. Three kinds are told apart by dtype:

* times: ``datetime64[ms]``, UTC (NaT where a row has none); pandas gets them as ``datetime64[ms, UTC]``;
* text: an object array of ``str`` or ``None``; pandas gets them as its Arrow-backed ``str`` dtype. A text column
  of a few names (a satellite's constellation) is held as :class:`Coded` (small integer codes into the names) and
  given out decoded;
* numbers and booleans as they are.

``tollcli epochs`` and ``tollcli info`` read and write such tables without importing pandas (0.3 s of every
run); :meth:`Columns.to_pandas` gives the DataFrame the integrity checks and the charging read, and
:func:`as_columns` turns a DataFrame back (the readers that build frames themselves).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

import numpy as np

UTC_MS = np.dtype("datetime64[ms]")


class Coded:
    """A text column of few distinct values: ``codes`` (integers) index ``names``."""

    __slots__ = ("codes", "names")

    def __init__(self, codes: np.ndarray, names: tuple[str, ...]):
        self.codes, self.names = np.asarray(codes), tuple(names)

    def __len__(self) -> int:
        return len(self.codes)

    def decoded(self) -> np.ndarray:
        """The object array of the names."""
        return np.array(self.names, dtype=object)[self.codes]


class Columns:
    """Named numpy arrays of one length, in order (see the module); a :class:`Coded` column is given out decoded."""

    __slots__ = ("_data",)

    def __init__(self, data: Mapping[str, np.ndarray]):
        self._data = dict(data)
        lengths = {len(v) for v in self._data.values()}
        if len(lengths) > 1:
            raise ValueError(f"columns of different lengths: {sorted(lengths)}")

    @property
    def columns(self) -> list[str]:
        return list(self._data)

    def __len__(self) -> int:
        return len(next(iter(self._data.values()))) if self._data else 0

    def __getitem__(self, name: str) -> np.ndarray:
        values = self._data[name]
        return values.decoded() if isinstance(values, Coded) else values

    def __contains__(self, name: object) -> bool:
        return name in self._data

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def items(self):
        """(name, column) pairs as held: numpy arrays, or :class:`Coded`."""
        return self._data.items()

    def held(self, name: str):
        """Column ``name`` as held: a numpy array, or :class:`Coded` (not decoded)."""
        return self._data[name]

    def to_pandas(self):
        """The DataFrame: times as ``datetime64[ms, UTC]``, text as pandas' Arrow-backed strings."""
        import pandas as pd

        return pd.DataFrame({name: _pandas_column(values) for name, values in self._data.items()})

    def to_arrow(self):
        """The pyarrow Table (times ``timestamp[ms, tz=UTC]``, text ``large_string``, NaN and NaT null: what
        ``pyarrow.Table.from_pandas`` gives of :meth:`to_pandas`, without its pandas metadata).

        The arrays are built from their buffers: ``pyarrow.array`` of numpy values imports pandas."""
        import pyarrow as pa

        return pa.Table.from_arrays([_arrow_column(v) for v in self._data.values()], names=list(self._data))


def is_time(values) -> bool:
    return not isinstance(values, Coded) and values.dtype.kind == "M"


def is_text(values) -> bool:
    return isinstance(values, Coded) or values.dtype == object


def _bits(mask: np.ndarray):
    """A boolean array → Arrow's bitmap buffer (least significant bit first)."""
    import pyarrow as pa

    return pa.py_buffer(np.packbits(mask, bitorder="little"))


def _arrow_column(values):
    """One column → a pyarrow array built from buffers (NaN and NaT null, as pandas' frame gives them)."""
    import pyarrow as pa

    if is_text(values):
        return _arrow_text(values)
    n = len(values)
    if is_time(values):
        kind, data, missing = pa.timestamp("ms", tz="UTC"), values.astype(UTC_MS).view(np.int64), np.isnat(values)
    elif values.dtype == bool:
        return pa.Array.from_buffers(pa.bool_(), n, [None, _bits(values)])
    else:
        kind, data = pa.from_numpy_dtype(values.dtype), values
        missing = np.isnan(values) if values.dtype.kind == "f" else np.zeros(n, bool)
    nulls = int(missing.sum())
    return pa.Array.from_buffers(kind, n, [_bits(~missing) if nulls else None, pa.py_buffer(np.ascontiguousarray(data))],
                                 null_count=nulls)  # fmt: skip


def _arrow_text(values):
    """A text column (object array or :class:`Coded`) → a ``large_string`` array built from its offsets and bytes."""
    import pyarrow as pa

    if isinstance(values, Coded):  # each name encoded once, the rows' bytes gathered by their codes
        names = [n.encode() for n in values.names] or [b""]
        width = max(len(b) for b in names) or 1
        table = np.zeros((len(names), width), np.uint8)
        for i, b in enumerate(names):
            table[i, : len(b)] = np.frombuffer(b, np.uint8)
        lengths = np.array([len(b) for b in names], np.int64)[values.codes]
        valid = None
        data = table[values.codes][np.arange(width) < lengths[:, None]].tobytes()
    else:
        items = values.tolist()
        encoded = [v.encode() if isinstance(v, str) else b"" for v in items]
        valid = np.fromiter((isinstance(v, str) for v in items), bool, len(items))
        lengths = np.fromiter(map(len, encoded), np.int64, len(encoded))
        data = b"".join(encoded)
    offsets = np.zeros(len(lengths) + 1, np.int64)
    np.cumsum(lengths, out=offsets[1:])
    nulls = 0 if valid is None else int((~valid).sum())
    return pa.Array.from_buffers(pa.large_string(), len(lengths), [_bits(valid) if nulls else None, pa.py_buffer(offsets),
                                                                    pa.py_buffer(data)], null_count=nulls)  # fmt: skip


def _pandas_column(values):
    import pandas as pd

    if is_time(values):
        return pd.DatetimeIndex(values.astype(UTC_MS)).tz_localize("UTC")
    if isinstance(values, Coded):
        return coded_text_array(values)
    if is_text(values):
        return text_array(values)
    return values


def coded_text_array(values: Coded):
    """A :class:`Coded` column → pandas' ``string`` column (a dictionary cast by pyarrow: no object array)."""
    import pandas as pd
    import pyarrow as pa

    if pd.StringDtype().storage != "pyarrow":  # pragma: no cover - pandas configured for Python strings
        return pd.array(values.decoded(), dtype="string")
    names = pa.DictionaryArray.from_arrays(pa.array(values.codes), pa.array(values.names, type=pa.string()))
    return pd.arrays.ArrowStringArray(names.cast(pa.string()))


def text_of_codes(codes: np.ndarray, names):
    """``pd.array(np.asarray(names, dtype=object)[codes], dtype="string")`` made from the codes (a negative code counts
    from the end, as numpy's indexing does): a status column of a few names without a Python string per row (about half
    the time for a chunk's 5 000 rows)."""
    names = tuple(names)
    codes = np.asarray(codes)
    if codes.size and (codes.min() < -len(names) or codes.max() >= len(names)):
        raise IndexError(f"a code outside the {len(names)} names")
    return coded_text_array(Coded(np.where(codes < 0, codes + len(names), codes), names))


def text_array(values: np.ndarray):
    """An object array of str/None → pandas' ``string`` column (Arrow-backed; built by pyarrow directly, faster)."""
    import pandas as pd
    import pyarrow as pa

    if pd.StringDtype().storage != "pyarrow":  # pragma: no cover - pandas configured for Python strings
        return pd.array(values, dtype="string")
    return pd.arrays.ArrowStringArray(pa.array(values, type=pa.string(), from_pandas=True))


def column_array(table, name: str, dtype=None) -> np.ndarray:
    """One column of a :class:`Columns` or a DataFrame as a numpy array (``dtype``: converted to it), so that code
    reading a table's numbers takes either without building the other."""
    values = table[name]
    if isinstance(table, Columns):
        return values if dtype is None else np.asarray(values, dtype=dtype)
    return values.to_numpy(dtype=dtype)


def sorted_codes(values: Coded) -> tuple[np.ndarray, np.ndarray]:
    """A :class:`Coded` column's codes renumbered in its names' sorted order, and those names (objects): what
    ``pandas.factorize(column, sort=True)`` gives, except that names no row has may be among them."""
    names = np.asarray(values.names, dtype=object)
    order = np.argsort(names, kind="stable")
    rank = np.empty(len(names), np.int64)
    rank[order] = np.arange(len(names))
    return rank[values.codes], names[order]


def as_columns(table) -> Columns:
    """A :class:`Columns` (returned as it is) or a DataFrame → :class:`Columns` (times to ``datetime64[ms]`` UTC,
    text to object arrays with ``None`` for missing)."""
    if isinstance(table, Columns):
        return table
    import pandas as pd

    data = {}
    for name in table.columns:
        col = table[name]
        if isinstance(col.dtype, pd.DatetimeTZDtype):
            data[name] = col.dt.tz_convert(None).to_numpy().astype(UTC_MS)
        elif col.dtype == object or isinstance(col.dtype, pd.StringDtype):
            data[name] = np.array([None if v is pd.NA or v is None or (isinstance(v, float) and v != v) else v
                                   for v in col.tolist()], dtype=object)  # fmt: skip
        else:
            data[name] = col.to_numpy()
    return Columns(data)
