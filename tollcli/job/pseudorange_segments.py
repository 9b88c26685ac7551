"""A pseudorange log solved and placed segment by segment: memory flat in the log's length.

libRSF logs, GSDC derived CSVs, u-blox RAWX logs, Android logs (GnssLogger text, GSDC ``device_gnss.csv``) and RINEX 2
and 3 observation files (:data:`SEGMENTED_KINDS`) are read this way; a RINEX file the direct readers leave to georinex
(the cases :mod:`tollcli.readers.rinex2_obs` and :mod:`tollcli.readers.rinex3_obs` name) is read and solved whole
(:func:`~tollcli.gnss.pseudorange_inputs.pseudorange_epochs`).

The log is read in blocks of rows (:func:`~tollcli.readers.librsf.iter_librsf`,
:func:`~tollcli.readers.gsdc.iter_gsdc_derived`, :func:`~tollcli.readers.ubx.iter_rawx` after a first pass over the
u-blox log for its navigation data, :func:`~tollcli.readers.gnsslogger.iter_gnsslogger`,
:func:`~tollcli.readers.gnsslogger.iter_device_gnss`, :func:`~tollcli.readers.rinex_obs.iter_observation_rows`
after a first pass that chooses each system's code: :mod:`tollcli.job.segment_formats`). Its epochs are cut into segments of
:data:`SEGMENT_EPOCHS` (the segment's *core*); each segment is solved (snapshot WLS) and placed by the trajectory
estimator (:func:`~tollcli.integrity.trajectory.with_trajectory`) together with :data:`MARGIN_EPOCHS` epochs before
and after its core — the passes converge there, the backward one from the future — and only its core is kept. The
noise the estimator measures from the residuals is then each segment's own (a long drive's noise changes as it
goes from motorway to city).

A core is :data:`SEGMENT_EPOCHS` epochs, or :data:`SEGMENT_MIN_S` where that is longer, and is cut only once
half as much again follows its margin after; a log shorter than that is one segment: solved and placed whole, the
same numbers as before segments existed. The last core takes what is left, so no segment is too short for a
trajectory.

The cores are written, as each is placed, to a private temporary directory (arrays, no pickles), and read back chunk
by chunk once every segment is placed: an invoice needs the log's longest correlation time (how far apart positions
are independent evidence) before its first chunk is charged. A log whose pseudorange or odometry lines are not in
time order cannot be cut by time: it is read and solved whole, as before.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, fields

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements
from tollcli.gnss.sigma_models import NominalModel
from tollcli.job.segment_formats import FORMATS, ReadWhole, SegmentFormat

#: pseudorange formats read and placed segment by segment
SEGMENTED_KINDS = ("librsf", "gsdc-derived", "ubx", "gnsslogger", "device-gnss", "rinex")
#: the epochs of a segment's core, at least …
SEGMENT_EPOCHS = 8_192
#: … and at least this long (s): the estimator measures the noise from a segment's own residuals, and on the Berlin
#: drive cut into segments of 100–190 s it measured too little (57 epochs beyond their bound)
SEGMENT_MIN_S = 1_800.0
#: the epochs solved and placed before and after a core, not kept
MARGIN_EPOCHS = 1_024
#: odometry samples kept beyond a segment's first and last epoch (ms): its intervals' integrals reach them
ODOMETRY_PAD_MS = 2_000


@dataclass
class PlacedLog:
    """A pseudorange log's placed epochs and measurements: :meth:`chunks` hands them over in order.

    ``positioning``: the positioning used (of every segment; "smoothed" where any was placed by it and a note names
    the others); ``note``: why a trajectory did not place (some of) the epochs; ``correlation_s``: the longest
    correlation time of the trajectory's errors (None: no trajectory); ``skipped_lines``: malformed lines the reader
    passed over; ``segments``: how many segments the log was placed in."""

    positioning: str
    note: str | None
    correlation_s: float | None
    skipped_lines: int
    segments: int = 1
    _whole: tuple[pd.DataFrame, Measurements] | None = None
    _folder: str | None = None
    _stored: list[str] = field(default_factory=list)

    def chunks(self, chunk_epochs: int) -> Iterator[tuple[pd.DataFrame, Measurements]]:
        """The epochs and measurements, ``chunk_epochs`` epochs at a time (each table indexed from 0, its ``attrs``
        the log's skipped lines and, where a trajectory placed it, its correlation time)."""
        attrs = {"skipped_lines": self.skipped_lines}
        if self.note:
            attrs["positioning_note"] = self.note
        if self.correlation_s is not None:
            attrs["trajectory_correlation_s"] = self.correlation_s
        if self._whole is not None and not len(self._whole[0]):  # a log without an epoch: its empty table, once
            self._whole[0].attrs.update(attrs)
            yield self._whole
            return
        parts = [self._whole] if self._whole is not None else (_load(path) for path in self._stored)
        for epochs, meas in parts:
            for part, part_meas in epoch_chunks(epochs, meas, chunk_epochs):
                part.attrs = {**epochs.attrs, **attrs}  # (a log placed whole keeps whatever else its table says)
                yield part, part_meas

    def close(self) -> None:
        """Remove the stored segments (if any)."""
        self._folder = _removed(self._folder)

    def __enter__(self) -> PlacedLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def epoch_chunks(epochs: pd.DataFrame, meas: Measurements, chunk_epochs: int) -> Iterator[tuple[pd.DataFrame, Measurements]]:
    """A log's epoch table and measurements, ``chunk_epochs`` epochs at a time (each table indexed from 0)."""
    for start in range(0, len(epochs), chunk_epochs):
        rows = np.arange(start, min(start + chunk_epochs, len(epochs)))
        yield epochs.iloc[rows].reset_index(drop=True), meas.take(rows)


def placed_log(log: str, kind: str, nav, sigma_model: str, sigma_m: float, nominal: NominalModel, strict: bool,
               positioning: str) -> PlacedLog:  # fmt: skip
    """A pseudorange log ``log`` of format ``kind`` solved and placed (``positioning``, as
    :func:`~tollcli.integrity.trajectory.with_trajectory` takes it): segment by segment where the format allows
    (see the module), else whole. Raises what :func:`~tollcli.gnss.pseudorange_inputs.pseudorange_epochs` raises."""
    if kind in SEGMENTED_KINDS:
        segmented = _segments(FORMATS[kind](nav), log, sigma_model, sigma_m, nominal, strict, positioning)
        if segmented is not None:
            return segmented
    from tollcli.gnss.pseudorange_inputs import pseudorange_epochs

    epochs, meas = pseudorange_epochs(log, kind, nav, sigma_model, sigma_m, nominal, strict)
    return _whole(epochs, meas, positioning, int(epochs.attrs.get("skipped_lines", 0)))


def _whole(epochs: pd.DataFrame, meas: Measurements, positioning: str, skipped: int) -> PlacedLog:
    from tollcli.integrity.trajectory import with_trajectory

    epochs, meas, used = with_trajectory(epochs, meas, positioning)
    epochs.attrs["skipped_lines"] = skipped
    return PlacedLog(used, epochs.attrs.get("positioning_note"), epochs.attrs.get("trajectory_correlation_s"), skipped,
                     _whole=(epochs, meas))  # fmt: skip




def _segments(fmt: SegmentFormat, log: str, sigma_model: str, sigma_m: float, nominal: NominalModel, strict: bool,
              positioning: str) -> PlacedLog | None:  # fmt: skip
    """A log placed segment by segment; None where its lines are not in time order (read it whole)."""
    from tollcli.errors import DataError

    if fmt.check is not None:
        fmt.check(sigma_model)
    cutter = _Cutter(fmt.keys)
    placer = _Placer(fmt, positioning, sigma_model, sigma_m, nominal, log)
    skipped = 0
    try:
        for rows, odometry, malformed in fmt.blocks(log, strict):
            skipped += malformed
            for part, odo, core in cutter.add(rows, odometry):
                placer.place(part, odo, core)
        rows, odometry, core = cutter.rest()
        if rows is None:
            raise DataError(f"{log}: {fmt.no_rows}")
        if placer.n_segments == 0:  # one segment: the log solved and placed whole, as before segments existed
            placer.close()
            return _whole(*fmt.solve(rows, odometry, sigma_model, sigma_m, nominal), positioning, skipped)
        placer.place(rows, odometry, core)
        placer.check_orbits()
    except BaseException as exc:  # nothing stored is left behind, whatever stopped the placing
        placer.close()
        if isinstance(exc, ReadWhole):
            return None
        if isinstance(exc, DataError) and not exc.args[0].startswith(log):
            raise DataError(f"{log}: {exc}") from None
        raise  # (a DataError naming the log as it is: its kind, NoOrbitsError, is what the caller acts on)
    return placer.finish(skipped)


class _Cutter:
    """Rows in, segments out: the measurement and odometry rows of each segment (its margins included) and its core's
    first epoch key and the first after it (None: the log's end). ``keys``: the rows' epoch keys (ms)."""

    def __init__(self, keys: Callable[[pd.DataFrame], np.ndarray]):
        self.row_keys = keys
        self.rows: list[pd.DataFrame] = []
        self.odo: list[pd.DataFrame] = []
        self.keys = np.zeros(0, np.int64)  # the distinct epoch keys of the rows held, in order
        self.last_row = self.last_odo = np.iinfo(np.int64).min
        self.lead = 0  # the epochs of the held rows before the next core (its margin before)

    def add(self, rows: pd.DataFrame, odo: pd.DataFrame | None):
        for table, attr in ((rows, "last_row"), (odo, "last_odo")):
            k = self.row_keys(table) if table is not None and len(table) else np.zeros(0, np.int64)
            if k.size and (k[0] < getattr(self, attr) or (np.diff(k) < 0).any()):
                raise ReadWhole("its lines are not in time order")
            if k.size:
                setattr(self, attr, int(k[-1]))
        if len(rows):
            self.rows.append(rows)
            k = np.unique(self.row_keys(rows))
            self.keys = np.concatenate([self.keys, k[k > self.keys[-1]] if self.keys.size else k])
        if odo is not None and len(odo):
            self.odo.append(odo)
        # a core is cut once half a segment is held beyond it and its margin after: the last core is never short
        while (hi := self._core_end()) is not None:
            yield self._cut(hi)

    def _core_end(self) -> int | None:
        """The index of the first held key after the next core, once half a segment is held beyond its margin."""
        keys, lo = self.keys, self.lead
        hi = lo + SEGMENT_EPOCHS
        if hi >= keys.size:
            return None
        hi = max(hi, int(np.searchsorted(keys, keys[lo] + SEGMENT_MIN_S * 1e3)))
        after = hi + MARGIN_EPOCHS
        if after + SEGMENT_EPOCHS // 2 >= keys.size or keys[-1] - keys[after] < SEGMENT_MIN_S * 1e3 / 2:
            return None
        return hi

    def _cut(self, hi: int):
        core_lo, core_hi = int(self.keys[self.lead]), int(self.keys[hi])
        end = int(self.keys[hi + MARGIN_EPOCHS])  # the first key after the segment
        start = int(self.keys[hi - MARGIN_EPOCHS])  # the next segment's first epoch
        rows = pd.concat(self.rows, ignore_index=True)
        rk = self.row_keys(rows)
        segment_rows, self.rows = rows[rk < end].reset_index(drop=True), [rows[rk >= start].reset_index(drop=True)]
        segment_odo = None
        if self.odo:
            odo = pd.concat(self.odo, ignore_index=True)
            ok = self.row_keys(odo)
            segment_odo, self.odo = odo[ok < end + ODOMETRY_PAD_MS].reset_index(drop=True), [odo[ok >= start - ODOMETRY_PAD_MS].reset_index(drop=True)]
        self.keys = self.keys[self.keys >= start]
        self.lead = MARGIN_EPOCHS
        return segment_rows, segment_odo, (core_lo, core_hi)

    def rest(self):
        """The last segment (the log's only one when none was cut): rows, odometry (None: none) and core."""
        if not self.rows:
            return None, None, None
        odo = pd.concat(self.odo, ignore_index=True) if self.odo else None
        return pd.concat(self.rows, ignore_index=True), odo, (int(self.keys[self.lead]), None)


class _Placer:
    """Each segment solved, placed and its core stored; what the segments said, gathered."""

    def __init__(self, fmt: SegmentFormat, positioning: str, sigma_model: str, sigma_m: float, nominal: NominalModel, log: str):
        self.fmt, self.positioning, self.sigma_model, self.sigma_m, self.nominal = fmt, positioning, sigma_model, sigma_m, nominal
        self.log = log  # (a note does not name it: it may be a run's copy of the log)
        self.folder: str | None = None
        self.stored: list[str] = []
        self.n_segments = 0
        self.n_epochs = 0
        self.used: list[str] = []
        self.notes: list[str] = []
        self.correlation_s: float | None = None
        self.with_orbits = False  # whether a segment had a measurement with an orbit
        self.no_orbits: Exception | None = None  # the first segment's error where one had none

    def place(self, rows: pd.DataFrame, odo: pd.DataFrame | None, core: tuple[int, int | None]) -> None:
        """Solve and place a segment's ``rows`` (and odometry ``odo``), and store the epochs of its ``core`` (its first
        epoch key and the first key after it, ms; None: to the end)."""
        from tollcli.gnss.satellite_states import NoOrbitForRows
        from tollcli.integrity.trajectory import with_trajectory

        missing = None
        try:
            epochs, meas = self.fmt.solve(rows, odo, self.sigma_model, self.sigma_m, self.nominal)
            self.with_orbits = True
        except NoOrbitForRows as exc:  # (its epochs without positions, as they are in the whole log: said in the note)
            self.no_orbits, missing = self.no_orbits or exc, exc
            epochs, meas = self.fmt.solve(rows, odo, self.sigma_model, self.sigma_m, self.nominal, orbits_required=False)
        epochs, meas, used = with_trajectory(epochs, meas, self.positioning)
        if used == "snapshot" and self.positioning != "snapshot":  # refused here: the columns of the placed segments
            epochs = epochs.assign(snapshot_lat_deg=epochs["lat_deg"].to_numpy(float), snapshot_lon_deg=epochs["lon_deg"].to_numpy(float),
                                   sigma_major_m=np.nan, positioning=np.full(len(epochs), "snapshot", dtype=object))  # fmt: skip
        keys = self.fmt.epoch_keys(epochs)
        rows = np.flatnonzero((keys >= core[0]) & (keys < core[1] if core[1] is not None else True))
        part = epochs.iloc[rows].reset_index(drop=True)
        part["epoch"] = np.arange(self.n_epochs, self.n_epochs + len(part), dtype=np.int64)
        if self.folder is None:
            self.folder = tempfile.mkdtemp(prefix="tollcli-segments-")
        path = os.path.join(self.folder, f"segment-{self.n_segments:05d}")
        try:
            _store(path, part, meas.take(rows))
        except OSError as exc:  # (a disk full: said as the system's refusal, with where the segments go)
            raise OSError(exc.errno, f"{exc.strerror or exc} (a long log's segments wait there, about 2.3 kB an epoch, until "
                                     "they are charged: TMPDIR names a larger disk)", exc.filename) from None  # fmt: skip
        self.stored.append(path)
        self.used.append(used)
        note = str(missing).removeprefix(f"{self.log}: ") if missing is not None else epochs.attrs.get("positioning_note")
        if note:
            self.notes.append(f"epochs {self.n_epochs}–{self.n_epochs + len(part) - 1}: {note}")
        if "trajectory_correlation_s" in epochs.attrs:
            self.correlation_s = max(self.correlation_s or 0.0, float(epochs.attrs["trajectory_correlation_s"]))
        self.n_segments += 1
        self.n_epochs += len(part)

    def check_orbits(self) -> None:
        """Raise the first segment's error where no segment had a measurement with an orbit (the log's error read
        whole; it names that segment's time span)."""
        if not self.with_orbits and self.no_orbits is not None:
            raise self.no_orbits

    def finish(self, skipped: int) -> PlacedLog:
        used = sorted(set(self.used))
        positioning = used[0] if len(used) == 1 else next(u for u in self.used if u != "snapshot")
        note = "; ".join(self.notes) if self.notes else None
        return PlacedLog(positioning, note, self.correlation_s, skipped, self.n_segments, _folder=self.folder, _stored=self.stored)

    def close(self) -> None:
        self.folder = _removed(self.folder)


def _removed(folder: str | None) -> None:
    """Remove the segments' folder (if any); None, the folder it leaves."""
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


def _store(path: str, epochs: pd.DataFrame, meas: Measurements) -> None:
    """A segment's core, written as arrays: the epoch table's columns and the measurements' (text as Unicode)."""
    os.mkdir(path)
    columns = []
    for name in epochs.columns:
        values = epochs[name]
        if isinstance(values.dtype, pd.DatetimeTZDtype):
            np.save(os.path.join(path, f"epochs.{len(columns)}.npy"), values.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(),
                    allow_pickle=False)  # fmt: skip
            columns.append((name, "utc"))
        else:
            a = values.to_numpy()
            text = a.dtype == object
            np.save(os.path.join(path, f"epochs.{len(columns)}.npy"), a.astype(str) if text else a, allow_pickle=False)
            columns.append((name, "text" if text else "array"))
    with open(os.path.join(path, "columns.txt"), "w", encoding="utf-8") as f:
        f.write("\n".join(f"{kind}\t{name}" for name, kind in columns))
    for f_ in fields(meas):
        value = getattr(meas, f_.name)
        if value is None:
            continue
        if not isinstance(value, np.ndarray):
            raise TypeError(f"a segment's measurements hold a {type(value).__name__} ({f_.name}): not stored as an array")
        text = value.dtype == object
        np.save(os.path.join(path, f"meas.{f_.name}{'.text' if text else ''}.npy"), value.astype(str) if text else value, allow_pickle=False)


def _load(path: str) -> tuple[pd.DataFrame, Measurements]:
    """A stored segment's core (:func:`_store`)."""
    with open(os.path.join(path, "columns.txt"), encoding="utf-8") as f:
        columns = [line.split("\t", 1) for line in f.read().split("\n") if line]
    data = {}
    for i, (kind, name) in enumerate(columns):
        a = np.load(os.path.join(path, f"epochs.{i}.npy"), allow_pickle=False)
        data[name] = pd.DatetimeIndex(a).tz_localize("UTC") if kind == "utc" else a.astype(object) if kind == "text" else a
    epochs = pd.DataFrame(data)
    given = {}
    for name in os.listdir(path):
        if name.startswith("meas."):
            stem = name[len("meas.") : -len(".npy")]
            a = np.load(os.path.join(path, name), allow_pickle=False)
            if stem.endswith(".text"):
                stem, a = stem[: -len(".text")], a.astype(object)
            given[stem] = a
    return epochs, Measurements(**given)
