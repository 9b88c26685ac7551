"""A receiver log → epoch tables with the RAIM columns, chunk by chunk (shared by ``integrity``, ``locate``, ``findings``)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator

import numpy as np
import pandas as pd

from tollcli.errors import UsageError
from tollcli.geodesy import enu_shift2geodetic
from tollcli.gnss.nmea_measurements import AngleCarry, nmea_measurements
from tollcli.gnss.pseudorange_inputs import NoOrbitsError
from tollcli.gnss.sigma_models import NominalModel
from tollcli.integrity.environment import EnvironmentCarry, with_environment
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim, settle_sources
from tollcli.io.columns import Columns
from tollcli.io.prefetch import read_ahead
from tollcli.job.pseudorange_segments import placed_log
from tollcli.readers.navigation import NAVIGATION_KINDS, iter_navigation_tables
from tollcli.readers.nmea import ReadStats


class IntegrityChunk:
    """A chunk's integrity table (epochs + RAIM columns + ``raim_lat_deg``/``raim_lon_deg``) and its satellite table
    (the NMEA reader's, of the same epochs; None for pseudorange inputs), the latter made a DataFrame only when asked
    for (``tollcli integrity`` never asks: 0.25–0.3 s of a 10 h drive)."""

    __slots__ = ("table", "_satellites")

    def __init__(self, table: pd.DataFrame, satellites: pd.DataFrame | Columns | None):
        self.table, self._satellites = table, satellites

    @property
    def satellites(self) -> pd.DataFrame | None:
        if isinstance(self._satellites, Columns):
            self._satellites = self._satellites.to_pandas()
        return self._satellites


def with_raim_position(table: pd.DataFrame) -> pd.DataFrame:
    """Add ``raim_lat_deg``/``raim_lon_deg``: the position the RAIM vouches for (its own weighted solution, after any
    exclusion)."""
    east = table["fde_shift_e_m"].to_numpy(float) + table["wls_shift_e_m"].to_numpy(float)
    north = table["fde_shift_n_m"].to_numpy(float) + table["wls_shift_n_m"].to_numpy(float)
    lat, lon = enu_shift2geodetic(table["lat_deg"].to_numpy(float), table["lon_deg"].to_numpy(float), east, north)
    return table.assign(raim_lat_deg=lat, raim_lon_deg=lon)


#: the epochs of a pseudorange log checked at a time (its positions are solved and placed for the whole log first): the
#: RAIM's working set — the subsets' solutions of every epoch — is a chunk's (``integrity`` of a 40 000-epoch log
#: peaked in the RAIM over all of it at once)
RAIM_CHUNK_EPOCHS = 3_600


def iter_integrity(log, kind: str, params: RaimParams, sigma_model: str = "nominal", sigma_m: float = 5.0,
                   nominal: NominalModel | None = None, strict: bool = False, stats: ReadStats | None = None,
                   nav: str | tuple[str, ...] | None = None, date: dt.date | None = None, environment: str = "auto",
                   positioning: str = "auto") -> Iterator[IntegrityChunk]:  # fmt: skip
    """Integrity tables of ``log`` (``kind``: a navigation kind — nmea, ubx-nav, gpsd-json — streamed in chunks, or a
    pseudorange format). ``log``: a path, or the log's :class:`~tollcli.io.log_run.LogRun` (read through it: opened once).

    ``date``: the UTC date of the first epoch, for NMEA logs without RMC/ZDA dates. ``environment``: auto
    (each epoch's class from its residuals, :mod:`tollcli.integrity.environment`), open or urban. ``positioning``: a
    pseudorange log's (:func:`~tollcli.integrity.trajectory.with_trajectory`).
    """
    from tollcli.io.log_run import LogRun

    nominal = nominal or NominalModel()
    if isinstance(log, LogRun):
        with log.named_errors():
            yield from iter_integrity(log.replay_path() if kind not in NAVIGATION_KINDS else log.source(), kind, params, sigma_model,
                                      sigma_m, nominal, strict, stats, nav, date, environment, positioning)  # fmt: skip
        return
    if kind not in NAVIGATION_KINDS:
        try:
            placed = placed_log(log, kind, nav, sigma_model, sigma_m, nominal, strict, positioning)
        except NoOrbitsError as exc:
            from tollcli.job.file_info import solutions_instead

            solutions = solutions_instead(log, kind, nav)
            if not solutions:
                raise
            note = f"{exc}: the receiver's own solutions ({', '.join(solutions)}) are read instead; --nav gives the orbits"
            for chunk in iter_integrity(log, "ubx-nav", params, sigma_model, sigma_m, nominal, strict, stats, None, date, environment):
                chunk.table.attrs.update(positioning_note=note, positioning_used="receiver")
                yield chunk
            return
        env_carry = EnvironmentCarry()
        with placed:  # (a long libRSF or GSDC log placed segment by segment: its segments removed on leaving)
            for part, part_meas in placed.chunks(RAIM_CHUNK_EPOCHS):  # the RAIM's working set a chunk's, not the log's
                part_meas, env_columns = measured_environment(part, part_meas, environment, env_carry)
                table = with_raim_position(pd.concat([part, env_columns, run_raim(part_meas, params)], axis=1))
                table.attrs["skipped_lines"] = placed.skipped_lines
                if placed.note:  # why no trajectory placed the epochs
                    table.attrs["positioning_note"] = placed.note
                yield IntegrityChunk(table, None)
        return
    if sigma_model == "input":
        raise UsageError("--sigma-model input: NMEA logs carry no per-measurement σ; use nominal or constant")
    carry, env_carry = AngleCarry(), EnvironmentCarry()
    read = iter_navigation_tables(log, kind, strict=strict, stats=stats if stats is not None else ReadStats(), date=date)
    measured = ((chunk, nmea_measurements(chunk.epochs, chunk.satellites_read, sigma_model, sigma_m, nominal, carry)) for chunk in read)
    with read_ahead(measured) as read:  # the next chunk read and measured while this one is checked
        for chunk, meas in read:
            params = settle_sources(params, meas)  # the level is the log's, from its first epoch with a source
            meas, env_columns = measured_environment(chunk.epochs, meas, environment, env_carry)
            raim = run_raim(meas, params)
            table = chunk.epochs.rename(columns={"n_used": "n_used_receiver"}).reset_index(drop=True)
            yield IntegrityChunk(with_raim_position(pd.concat([table, env_columns, raim], axis=1)), chunk.satellites_read)


#: what an integrity table's summary counts: (kind, column)
TALLIED_COLUMNS = (("status", "raim_status"), ("source", "integrity_source"), ("note", "gst_rms_note"),
                   ("environment", "environment"))


def tally_verdicts(table: pd.DataFrame, counts) -> None:
    """Add to ``counts`` (a Counter of (kind, value)) the statuses, deciding sources, GST RMS notes and environments of
    an integrity table (:data:`TALLIED_COLUMNS`), a column at a time: each value once, in the order the rows first give
    it (the counts and their order are those of counting row by row)."""
    for kind, column in TALLIED_COLUMNS:
        codes, values = pd.factorize(table[column].astype(str))
        counts.update({(kind, v): int(n) for v, n in zip(values, np.bincount(codes, minlength=len(values)))})


def measured_environment(epochs: pd.DataFrame, meas, setting: str, carry: EnvironmentCarry | None = None):
    """``meas`` with the urban σ on the epochs whose residuals say urban, and the ``environment`` and
    ``variance_factor`` columns (one row per epoch, index 0…)."""
    from tollcli.times import epoch_seconds

    try:
        meas, env, factor = with_environment(meas, epoch_seconds(epochs), setting, carry)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return meas, pd.DataFrame({"environment": pd.array(env, dtype="string"), "variance_factor": factor})


def with_epoch_checks(table: pd.DataFrame, roads: str | None) -> pd.DataFrame:
    """The speed, map-matching and HIT columns added to a whole trip's integrity table (``integrity --checks``)."""
    import numpy as np

    from tollcli.geodesy import geodetic2enu
    from tollcli.integrity.kalman_hit import hit
    from tollcli.integrity.map_matching import load_roads
    from tollcli.integrity.verdict import epoch_checks
    from tollcli.times import epoch_seconds

    if table.empty:
        return table
    if "speed_mps" not in table:
        table = table.assign(speed_mps=np.nan)
    extra = epoch_checks(table, load_roads(roads) if roads else None)
    lat, lon = table["lat_deg"].to_numpy(float), table["lon_deg"].to_numpy(float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    lat0, lon0 = (lat[ok][0], lon[ok][0]) if ok.any() else (0.0, 0.0)
    east, north, _ = geodetic2enu(np.where(ok, lat, lat0), np.where(ok, lon, lon0), 0.0, lat0, lon0, 0.0)
    sigma = table["sigma_major_m"].to_numpy(float) if "sigma_major_m" in table else None
    k = hit(np.where(ok, east, np.nan), np.where(ok, north, np.nan), table["speed_mps"].to_numpy(float), epoch_seconds(table), sigma)
    return pd.concat([table.reset_index(drop=True), extra, k[["hit_m"]]], axis=1)


def trip_tables(log, hal: float, strict: bool, date=None) -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """The whole trip's integrity table and satellite table (``log``: a path, or its LogRun: read once), for
    ``locate``, ``findings`` and ``enforce``."""
    from tollcli.io.log_run import LogRun
    from tollcli.readers.nmea.reader import check_usable

    if not isinstance(log, LogRun):
        with LogRun(log) as run:
            return trip_tables(run, hal, strict, date)
    kind = log.kind
    stats = ReadStats()
    tables, sats = [], []
    for chunk in iter_integrity(log, kind, RaimParams(hal_m=hal), strict=strict, stats=stats, date=date.date() if date else None):
        tables.append(chunk.table)
        if chunk.satellites is not None:
            sats.append(chunk.satellites)
    if kind in NAVIGATION_KINDS:
        check_usable(stats)
    table = pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()
    return table, (pd.concat(sats, ignore_index=True) if sats else None)
