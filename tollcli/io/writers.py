"""Write tables chunk by chunk to CSV, Parquet, GeoJSON or JSON — atomically.

A file is written under a temporary name in the same folder and renamed over
the target only when the whole table is written (:meth:`TableWriter.commit`); an
error or Ctrl-C leaves the old file, never half of a new one. ``-`` writes to
stdout (CSV unless a format is given), so commands compose in pipes.

Formats, by the output's extension:

* ``.csv``: header + rows; times as ISO 8601 UTC (``2024-05-01T12:00:00.000Z``),
  missing values empty;
* ``.parquet``: one row group per chunk, column types kept;
* ``.geojson``: a FeatureCollection of points (``lon_deg``, ``lat_deg``; rows
  without a position get ``"geometry": null``), other columns as properties;
* ``.geojsonl`` / ``.geojsons`` (GDAL's GeoJSONSeq): one point Feature per line — a stream;
* ``.json``: an array of row objects.

``-f/--format`` names the format whatever the name (``csv``, ``parquet``, ``geojson``, ``geojsonseq``,
``json``; GDAL's driver names ``CSV``, ``Parquet``, ``GeoJSON``, ``GeoJSONSeq`` too). A path that is not a
regular file (``/dev/null``, ``/dev/stdout``, a named pipe) is written to directly: nothing to rename.
Why this file is long: the five formats share one writer's life cycle (temporary file, commit, discard,
signals held while a temporary file is named), which is the part that must not be duplicated.

Floats in CSV are written with 15 significant digits: every number a log wrote comes back as written
(``42.6987``, not ``42.698699999999995``); Parquet keeps the doubles.

A chunk is a pandas DataFrame or a :class:`~tollcli.io.columns.Columns` (what the readers give): the second is
written without importing pandas, to the same CSV, JSON and GeoJSON bytes (``tests/test_columns.py`` holds them
to it on real logs) and the same Parquet columns, types and values (without pandas' own metadata: pandas reads
their text back as its default ``str``).
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import signal
import stat
import sys
import tempfile
import threading
from typing import IO

import numpy as np

from tollcli.errors import UsageError
from tollcli.io.columns import Columns, is_text, is_time

FORMATS = ("csv", "parquet", "geojson", "geojsonseq", "json")
_EXTENSIONS = {".csv": "csv", ".parquet": "parquet", ".pq": "parquet", ".geojson": "geojson", ".json": "json",
               ".geojsonl": "geojsonseq", ".geojsons": "geojsonseq", ".geojsonseq": "geojsonseq"}
#: what a CSV float is written as: 15 significant digits, the most any decimal keeps through a double
CSV_FLOAT = "%.15g"


def _umask_mode() -> int:
    """The mode a plainly created file would get (temporary files are 0600 until renamed)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def is_stream(path: str) -> bool:
    """``-``, or a path that is no regular file (``/dev/null``, ``/dev/stdout``, a FIFO): written to directly."""
    if path == "-":
        return True
    try:
        return not stat.S_ISREG(os.stat(path).st_mode) and not os.path.isdir(path)
    except OSError:
        return False


def format_for(path: str, default: str = "csv", fmt: str | None = None, allowed: tuple[str, ...] = FORMATS) -> str:
    """The format of an output: ``fmt`` (``-f``) when given, else the path's extension (``-`` or a device without
    one: ``default``); a UsageError for a format not in ``allowed``."""
    if fmt:
        name = fmt.lower()
        if name not in allowed:
            raise UsageError(f"-f {fmt}: this output can be {', '.join(allowed)}")
        return name
    ext = os.path.splitext(path)[1].lower() if path != "-" else ""
    if ext in _EXTENSIONS and _EXTENSIONS[ext] in allowed:
        return _EXTENSIONS[ext]
    if is_stream(path) and not ext:
        return default
    exts = ", ".join(e for e, f in _EXTENSIONS.items() if f in allowed and e not in (".pq", ".geojsons", ".geojsonseq"))
    raise UsageError(f"{path}: unknown output format {ext or '(no extension)'!r}; use {exts}, or name it with -f")


def iso_utc(values) -> np.ndarray:
    """UTC timestamps (a pandas Series) → ISO 8601 strings with ms and ``Z`` ('' for NaT)."""
    raw = values.dt.tz_convert(None).to_numpy().astype("datetime64[ms]")
    text = np.datetime_as_string(raw, unit="ms").astype(object)
    text = np.where(np.isnat(raw), "", text + "Z")
    return text


def _iso_ms(values: np.ndarray) -> list[str]:
    """``datetime64`` (UTC) → ISO 8601 strings with ms and ``Z`` ('' for NaT)."""
    return ["" if t == "NaT" else t + "Z" for t in np.datetime_as_string(values.astype("datetime64[ms]"), unit="ms").tolist()]


def _json_ready(df) -> list[dict]:
    """Rows as dicts of JSON-safe values (NaN → None, times → ISO strings)."""
    if isinstance(df, Columns):
        return _json_ready_columns(df)
    import pandas as pd

    out = {}
    for name in df.columns:
        col = df[name]
        if isinstance(col.dtype, pd.DatetimeTZDtype):
            values = [v or None for v in iso_utc(col)]
        else:
            values = []
            for v in col.tolist():
                if v is pd.NA or (isinstance(v, float) and not math.isfinite(v)):
                    v = None
                values.append(v)
        out[name] = values
    names = list(out)
    return [dict(zip(names, row)) for row in zip(*out.values())]


def _json_ready_columns(table: Columns) -> list[dict]:
    """:func:`_json_ready` of a :class:`Columns`: the same values, without pandas."""
    out = {}
    for name in table:
        values = table[name]
        if is_time(values):
            out[name] = [v or None for v in _iso_ms(values)]
        elif is_text(values):
            out[name] = [v if isinstance(v, str) else None for v in values.tolist()]
        elif values.dtype.kind == "f":
            out[name] = [v if math.isfinite(v) else None for v in values.tolist()]
        else:
            out[name] = values.tolist()
    names = list(out)
    return [dict(zip(names, row)) for row in zip(*out.values())]


def _csv_cells(values: np.ndarray) -> list:
    """One column of a :class:`Columns` as the cells pandas' ``to_csv`` writes for it (floats ``%.15g``, NaN and
    missing text empty, times ISO with ms and ``Z``, booleans ``True``/``False``)."""
    if is_time(values):
        return _iso_ms(values)
    if is_text(values):
        return [v if isinstance(v, str) else "" for v in values.tolist()]
    if values.dtype.kind == "f":
        return [CSV_FLOAT % v if v == v else "" for v in values.tolist()]
    return values.tolist()


def _write_utf8(fh: IO, data: bytes) -> None:
    """UTF-8 ``data`` appended to the text stream ``fh`` (opened UTF-8, no newline translation): to its byte buffer
    after what the text layer holds, not decoded to be encoded again (88 MB for a 10 h drive's satellite table)."""
    buffer = getattr(fh, "buffer", None)
    utf8 = (getattr(fh, "encoding", "") or "").lower().replace("-", "") == "utf8"
    if buffer is not None and utf8 and os.linesep == "\n":  # (where a text stream may turn "\n" into "\r\n": through it)
        fh.flush()
        buffer.write(data)
    else:
        fh.write(data.decode("utf-8"))


def _point_features(df):
    """Each row as a GeoJSON point Feature (``lon_deg``, ``lat_deg``; null geometry without a position)."""
    for row in _json_ready(df):
        lon, lat = row.get("lon_deg"), row.get("lat_deg")
        geometry = {"type": "Point", "coordinates": [lon, lat]} if lon is not None and lat is not None else None
        yield {"type": "Feature", "geometry": geometry, "properties": row}


class TableWriter:
    """Stream a table to ``path`` in ``fmt``; call :meth:`commit` when complete.

    Use as a context manager: leaving the block by an exception discards the
    temporary file; leaving it normally without :meth:`commit` discards it too.
    """

    def __init__(self, path: str, fmt: str | None = None, schema=None):
        """``schema``: Parquet only, the Arrow schema every chunk is cast to (else the first chunk's)."""
        self.path = path
        self.fmt = fmt or format_for(path)
        if self.fmt not in FORMATS:
            raise UsageError(f"unknown output format {self.fmt!r}")
        self._tmp: str | None = None
        self._fh: IO | None = None
        self._rows = 0
        self._parquet = None
        self._schema = schema
        self._committed = False
        self._columns: list[str] | None = None
        self._started = False  # header / opening bracket written
        self._records = 0  # JSON/GeoJSON records written (for separators)
        self._stream = is_stream(path)
        if not self._stream:
            folder = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(folder):
                raise UsageError(f"{path}: folder {folder} does not exist")
            if os.path.isdir(path):
                raise UsageError(f"{path}: is a directory, expected an output file")

    # -------------------------------------------------------------- lifecycle
    def __enter__(self) -> "TableWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self._committed:
            self.discard()

    def _open(self) -> IO:
        if self._fh is not None:
            return self._fh
        binary = self.fmt == "parquet"
        if self.path == "-":
            self._fh = sys.stdout.buffer if binary else sys.stdout
        elif self._stream:  # a device or a pipe: nothing to rename
            self._fh = open(self.path, "wb" if binary else "w", encoding=None if binary else "utf-8", newline=None if binary else "")
        else:
            folder = os.path.dirname(os.path.abspath(self.path))
            with signals_held():  # inside the writer's with-block: discard() removes it from here on
                fd, self._tmp = _temporary(self.path, folder)
            os.chmod(self._tmp, _umask_mode())
            self._fh = os.fdopen(fd, "wb" if binary else "w", encoding=None if binary else "utf-8", newline=None if binary else "")
        return self._fh

    def write(self, df) -> None:
        """Append a chunk (a DataFrame or :class:`~tollcli.io.columns.Columns`; same columns every time)."""
        if self._columns is None:
            self._columns = list(df.columns)
        fh = self._open()
        getattr(self, f"_write_{self.fmt}")(fh, df)
        self._rows += len(df)

    def commit(self) -> int:
        """Finish the file and move it into place; returns the number of rows."""
        fh = self._open()
        getattr(self, f"_close_{self.fmt}")(fh)
        fh.flush()
        if self._tmp is not None:
            os.fsync(fh.fileno())
            fh.close()
            os.replace(self._tmp, self.path)
            self._tmp = None
        elif self._stream and self.path != "-":
            fh.close()
        self._committed = True
        return self._rows

    def discard(self) -> None:
        """Drop what was written (the target file is left as it was)."""
        if self._parquet is not None:
            try:
                self._parquet.close()
            except Exception:  # noqa: BLE001 - discarding anyway
                pass
            self._parquet = None
        if self._tmp is not None:
            try:
                if self._fh is not None:
                    self._fh.close()
            finally:
                if os.path.exists(self._tmp):
                    os.unlink(self._tmp)
                self._tmp = None

    # -------------------------------------------------------------- CSV
    def _write_csv(self, fh: IO, df) -> None:
        if isinstance(df, Columns):
            from tollcli.io.csv_rows import csv_text

            rows = csv.writer(fh, lineterminator="\n")
            if not self._started:
                rows.writerow(df.columns)
            text = csv_text(df, _iso_ms)  # the compiled pass, else the csv module (the same bytes)
            if text is not None:
                _write_utf8(fh, text)
            else:
                rows.writerows(zip(*(_csv_cells(df[name]) for name in df)))
            self._started = True
            return
        import pandas as pd

        from tollcli.io.csv_rows import frame_csv_text

        out = df.copy(deep=False)
        for name in out.columns:
            if isinstance(out[name].dtype, pd.DatetimeTZDtype):
                out[name] = iso_utc(out[name])
        text = frame_csv_text(out)  # the compiled pass, else pandas (the same bytes)
        if text is None:
            out.to_csv(fh, index=False, header=not self._started, lineterminator="\n", float_format=CSV_FLOAT)
        else:
            if not self._started:
                csv.writer(fh, lineterminator="\n").writerow(out.columns)
            _write_utf8(fh, text)
        self._started = True

    def _close_csv(self, fh: IO) -> None:
        if not self._started and self._columns is not None:
            fh.write(",".join(self._columns) + "\n")

    # -------------------------------------------------------------- Parquet
    def _write_parquet(self, fh: IO, df) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if isinstance(df, Columns):
            table = df.to_arrow()
            if self._schema is not None and not table.schema.equals(self._schema):  # a cast imports pyarrow.compute
                table = table.cast(self._schema)
        else:
            table = pa.Table.from_pandas(df, preserve_index=False, schema=self._schema)
        if self._parquet is None:
            self._schema = table.schema
            self._parquet = pq.ParquetWriter(fh, self._schema)
        self._parquet.write_table(table)

    def _close_parquet(self, fh: IO) -> None:
        if self._parquet is None:
            raise UsageError("cannot write an empty table without columns to Parquet")
        self._parquet.close()
        self._parquet = None

    # -------------------------------------------------------------- GeoJSON
    def _write_geojson(self, fh: IO, df) -> None:
        if not self._started:
            fh.write('{"type": "FeatureCollection", "features": [\n')
            self._started = True
        for feature in _point_features(df):
            self._record(fh, feature)

    def _close_geojson(self, fh: IO) -> None:
        if not self._started:
            fh.write('{"type": "FeatureCollection", "features": [\n')
        fh.write("\n]}\n")

    # -------------------------------------------------------------- GeoJSON sequence
    def _write_geojsonseq(self, fh: IO, df) -> None:
        for feature in _point_features(df):
            fh.write(json.dumps(feature, separators=(",", ":"), allow_nan=False) + "\n")

    def _close_geojsonseq(self, fh: IO) -> None:
        pass

    # -------------------------------------------------------------- JSON
    def _write_json(self, fh: IO, df) -> None:
        if not self._started:
            fh.write("[\n")
            self._started = True
        for row in _json_ready(df):
            self._record(fh, row)

    def _close_json(self, fh: IO) -> None:
        if not self._started:
            fh.write("[\n")
        fh.write("\n]\n")

    def _record(self, fh: IO, obj: dict) -> None:
        """One JSON record, comma-separated from the previous one."""
        fh.write(("" if self._records == 0 else ",\n") + json.dumps(obj, separators=(",", ":"), allow_nan=False))
        self._records += 1


_HELD = (signal.SIGTERM, signal.SIGINT)
_holding = 0  # nesting depth of signals_held in the main thread
_pending: list[int] = []  # signals that arrived while held, in order


def _defer(signum, frame) -> None:
    _pending.append(signum)


@contextlib.contextmanager
def signals_held():
    """SIGTERM and SIGINT held back (delivered on leaving): a temporary file is created and its name kept in one step,
    so an interruption can never leave a temporary file nobody knows of.

    The deferral is in the handler, not in a signal mask: a signal sent to the process may be taken by any thread
    (numpy/OpenBLAS, pyarrow and Dask start some), and Python runs its handler in the main thread whatever thread
    took it. While held, the handlers only note the signal; on leaving the old handlers come back and each noted
    signal is raised again, once. Off the main thread (where handlers cannot be set) nothing is held.
    """
    global _holding
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if _holding:
        _holding += 1
        try:
            yield
        finally:
            _holding -= 1
        return
    old = {}
    for signum in _HELD:
        handler = signal.getsignal(signum)
        if handler is None or handler == signal.SIG_IGN:  # set outside Python, or ignored: nothing to defer
            continue
        old[signum] = signal.signal(signum, _defer)
    _holding = 1
    try:
        yield
    finally:
        _holding = 0
        for signum, handler in old.items():
            signal.signal(signum, handler)
        pending = list(dict.fromkeys(_pending))
        _pending.clear()
        for signum in pending:
            if signum in old:
                signal.raise_signal(signum)


def _temporary(path: str, folder: str) -> tuple[int, str]:
    """A temporary file beside ``path``; an OSError names ``path`` (the output), not the temporary name."""
    try:
        return tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise OSError(exc.errno, f"cannot write here ({exc.strerror})", path) from None


def output_folder(path: str, what: str = "outputs") -> str:
    """Make ``path`` a folder for ``what`` (created when missing); UsageError when a file is in the way."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise UsageError(f"{path}: is a file; -o names a folder for the {what}")
    os.makedirs(path, exist_ok=True)
    return path


def write_text_atomic(path: str, text) -> None:
    """Write a whole document (a string, or an iterable of its pieces): to stdout for ``-``, else to a temporary file
    renamed into place."""
    pieces = [text] if isinstance(text, str) else text
    if path == "-":
        for piece in pieces:
            sys.stdout.write(piece)
        return
    if is_stream(path):  # /dev/null, a pipe: nothing to rename
        with open(path, "w", encoding="utf-8", newline="") as fh:
            fh.writelines(pieces)
        return
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UsageError(f"{path}: folder {folder} does not exist")
    tmp = None
    try:
        with signals_held():  # created and named at once, inside the try that removes it
            fd, tmp = _temporary(path, folder)
        os.chmod(tmp, _umask_mode())
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.writelines(pieces)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        raise


class AtomicText:
    """A text file written line by line to a temporary file and renamed into place on :meth:`commit`."""

    def __init__(self, path: str):
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise UsageError(f"{path}: folder {folder} does not exist")
        self.path, self._folder = path, folder
        self._tmp: str | None = None
        self._fh: IO | None = None

    def __enter__(self) -> "AtomicText":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._tmp is not None:
            if self._fh is not None:
                self._fh.close()
            os.unlink(self._tmp)
            self._tmp = None

    def _open(self) -> IO:
        """The temporary file, made on first use (inside the with-block, whose exit removes it)."""
        if self._fh is None:
            with signals_held():
                fd, self._tmp = _temporary(self.path, self._folder)
            os.chmod(self._tmp, _umask_mode())
            self._fh = os.fdopen(fd, "w", encoding="utf-8", newline="")
        return self._fh

    def writelines(self, lines) -> None:
        self._open().writelines(line + "\n" for line in lines)

    def commit(self) -> None:
        self._open()
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self._fh.close()
        os.replace(self._tmp, self.path)
        self._tmp = None
