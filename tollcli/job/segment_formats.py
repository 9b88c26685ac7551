"""How each pseudorange format that is placed segment by segment is read and solved
(:mod:`tollcli.job.pseudorange_segments`): its rows a block at a time, each row's epoch key, a segment's rows solved
into epochs and measurements, and those epochs' keys."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements


class ReadWhole(Exception):
    """The log cannot be cut into segments (its lines are not in time order, or its reader reads it only whole): it is
    read and solved whole."""


@dataclass(frozen=True)
class SegmentFormat:
    """How a segmented format is read and solved: ``blocks(path, strict)`` its rows in file order, a block at a time
    (measurement rows, odometry rows or None — a u-blox log's: its receiver's fixes, carried the same way —, malformed
    lines); ``keys(rows)`` each row's epoch key (ms, int64);
    ``solve(rows, odometry, sigma_model, sigma_m, nominal, orbits_required=True)`` a segment's (epochs, measurements) —
    rows none of which has an orbit raise :class:`~tollcli.gnss.satellite_states.NoOrbitForRows`, or give epochs without
    positions — and ``epoch_keys`` those epochs' keys; ``no_rows``: the error of a log without a measurement; ``check(sigma_model)``, where set, refuses
    a σ model the format cannot give before the log is read."""

    blocks: Callable[[str, bool], Iterator[tuple[pd.DataFrame, pd.DataFrame | None, int]]]
    keys: Callable[[pd.DataFrame], np.ndarray]
    solve: Callable[..., tuple[pd.DataFrame, Measurements]]
    epoch_keys: Callable[[pd.DataFrame], np.ndarray]
    no_rows: str
    check: Callable[[str], None] | None = None  # refuses a σ model the format cannot give, before anything is read


def _librsf() -> SegmentFormat:
    from tollcli.gnss.librsf_positions import librsf_epochs
    from tollcli.readers.librsf import LIBRSF_T0, ODOMETRY_COLUMNS, LibrsfLog, iter_librsf

    def blocks(path, strict):
        for part in iter_librsf(path, strict):
            yield part.pseudoranges, part.odometry, part.malformed

    def solve(rows, odometry, sigma_model, sigma_m, nominal, orbits_required=True):  # (its orbits are in the log)
        if odometry is None:
            odometry = pd.DataFrame(np.zeros((0, len(ODOMETRY_COLUMNS))), columns=list(ODOMETRY_COLUMNS))
        return librsf_epochs(LibrsfLog(rows, odometry, pd.DataFrame(), 0), sigma_model, sigma_m, nominal)

    def epoch_keys(epochs):  # (librsf_epochs places epoch k ms after LIBRSF_T0 at time_utc: the key back, exactly)
        return ((epochs["time_utc"] - LIBRSF_T0) // pd.Timedelta(milliseconds=1)).to_numpy(np.int64)

    return SegmentFormat(blocks, lambda rows: np.round(rows["t_s"].to_numpy(float) * 1e3).astype(np.int64), solve, epoch_keys,
                   "no pseudorange3 line: a libRSF ground-truth file is a --truth, not a log")  # fmt: skip


def _gsdc_derived() -> SegmentFormat:
    from tollcli.gnss.gsdc_positions import gsdc_epochs
    from tollcli.readers.gsdc import iter_gsdc_derived

    def blocks(path, strict):
        for table in iter_gsdc_derived(path, strict):
            yield table, None, int(table.attrs["skipped_lines"])

    def solve(rows, _odometry, sigma_model, sigma_m, nominal, orbits_required=True):  # (its satellites are in the log)
        return gsdc_epochs(rows, sigma_model, sigma_m, nominal)

    return SegmentFormat(blocks, lambda rows: rows["millisSinceGpsEpoch"].to_numpy(np.int64), solve,
                   lambda epochs: epochs["gps_millis"].to_numpy(np.int64), "no usable rows")  # fmt: skip


def _ubx(nav) -> SegmentFormat:
    """A u-blox log in two passes: the first reads its navigation data and message times (not its measurements) for
    the orbits, keeping only the subframes, RAWX heads and NAV-PVT rows they can still read (``sfrbx_kept``,
    ``times_kept``), the second its RXM-RAWX and NAV-PVT a block of frames at a time. The receiver's own fixed solutions
    (NAV-PVT) go where a libRSF log's odometry goes: beside the rows, each segment with its own (their GPS times in ms
    its keys), matched to the segment's epochs when it is solved; none is kept for the whole log."""
    from tollcli.gnss.pseudorange_inputs import navigation_of, ubx_orbits
    from tollcli.gnss.raw_positions import raw_epochs, with_broadcast_satellites
    from tollcli.gnss.ubx_measurements import rawx_measurements, receiver_solutions, sfrbx_kept, times_kept, with_receiver_solution
    from tollcli.readers.ubx import UbxRead, iter_rawx, read_ubx

    known: dict = {}

    def blocks(path, strict):
        ephemerides, known["iono"] = navigation_of(nav)
        first = read_ubx(path, strict, measurements=False, subframes_kept=sfrbx_kept, times_kept=times_kept)  # what the orbits need
        known["orbits"] = ubx_orbits(path, first, ephemerides)
        damaged = first.n_bad  # (counted once: the first pass saw every frame)
        no_sfrbx, no_pvt = first.sfrbx.iloc[:0], first.pvt.iloc[:0]
        first = None  # (its subframes, NAV-PVT rows and RAWX times let go before the measurements are read)
        for rawx, pvt in iter_rawx(path, strict, with_pvt=True):
            rows = with_broadcast_satellites(rawx_measurements(UbxRead(rawx, no_sfrbx, no_pvt, 0, 0)), known["orbits"]) \
                if len(rawx) else pd.DataFrame()  # fmt: skip
            yield rows, receiver_solutions(pvt), damaged
            damaged = 0

    def solve(rows, fixes, sigma_model, sigma_m, nominal, orbits_required=True):
        epochs, meas = raw_epochs(rows, sigma_model, sigma_m, nominal, iono_coeffs=known["iono"], orbits_required=orbits_required)
        return with_receiver_solution(epochs, fixes), meas

    return SegmentFormat(blocks, lambda rows: rows["epoch_key"].to_numpy(np.int64), solve,
                   lambda epochs: epochs["gps_millis"].to_numpy(np.int64), "no RXM-RAWX measurements in the UBX log")  # fmt: skip


def _android(kind: str, nav) -> SegmentFormat:
    """An Android log, GnssLogger text (``Raw`` records; orbits from ``--nav``) or GSDC ``device_gnss.csv`` (orbits
    from its own satellite columns, or ``--nav``), its records a block at a time; an epoch's key its receiver time
    (ms), the same for every record of the epoch (one GnssClock)."""
    from tollcli.gnss.android_raw import raw_pseudoranges
    from tollcli.gnss.pseudorange_inputs import navigation_of
    from tollcli.gnss.raw_positions import raw_epochs, with_broadcast_satellites, with_device_gnss_satellites
    from tollcli.readers.gnsslogger import iter_device_gnss, iter_gnsslogger

    known: dict = {}

    def blocks(path, strict):
        ephemerides, known["iono"] = navigation_of(nav)
        if kind == "gnsslogger":
            if ephemerides is None:  # (read whole, where the error says so)
                raise ReadWhole("no orbits")
            for read in iter_gnsslogger(path, strict):
                rows = with_broadcast_satellites(raw_pseudoranges(read.raw), ephemerides) if read.raw is not None else pd.DataFrame()
                yield rows, None, read.n_malformed
            return
        for device in iter_device_gnss(path, strict):
            m = raw_pseudoranges(device)
            m = with_device_gnss_satellites(m, device) if ephemerides is None else with_broadcast_satellites(m, ephemerides)
            yield m[np.isfinite(m["t_rx_gps_s"].to_numpy(float))].reset_index(drop=True), None, int(device.attrs["skipped_lines"])

    def solve(rows, _odometry, sigma_model, sigma_m, nominal, orbits_required=True):
        return raw_epochs(rows, sigma_model, sigma_m, nominal, iono_coeffs=known["iono"], orbits_required=orbits_required)

    return SegmentFormat(blocks, lambda rows: np.round(rows["t_rx_gps_s"].to_numpy(float) * 1000).astype(np.int64), solve,
                         lambda epochs: epochs["gps_millis"].to_numpy(np.int64), "no measurement epochs")  # fmt: skip


def _rinex(nav) -> SegmentFormat:
    """A RINEX 2 or 3 observation file (orbits from ``--nav``), read directly in two passes: the first chooses each system's
    code, the second gives the rows a block of epochs at a time. A file the direct reader leaves to georinex, or
    without ``--nav``, is read whole (where those say what is wrong)."""
    from tollcli.gnss.pseudorange_inputs import is_rinex_navigation
    from tollcli.gnss.rinex_positions import check_sigma_model, rinex_rows_epochs
    from tollcli.gnss.satellite_states import load_navigation
    from tollcli.readers.gps_time import gps_seconds
    from tollcli.readers.rinex_obs import iter_observation_rows, observation_plan

    known: dict = {}

    def blocks(path, _strict):
        plan = observation_plan(path) if nav is not None and not is_rinex_navigation(path) else None
        if plan is None:
            raise ReadWhole("read by georinex, or not to be solved")
        known["ephemerides"], known["coeffs"], known["path"] = *load_navigation(nav), path
        for rows in iter_observation_rows(path, plan):
            yield rows, None, 0

    def solve(rows, _odometry, sigma_model, sigma_m, nominal, orbits_required=True):
        return rinex_rows_epochs(rows, known["ephemerides"], known["coeffs"], sigma_model, sigma_m, nominal, known["path"], nav,
                                 orbits_required)  # fmt: skip

    def millis(times) -> np.ndarray:
        return np.round(gps_seconds(np.asarray(times, "datetime64[ns]")) * 1000).astype(np.int64)

    return SegmentFormat(blocks, lambda rows: millis(rows["time"].to_numpy()), solve, lambda epochs: millis(epochs["time_gps"].to_numpy()),
                         "no pseudorange", check_sigma_model)  # fmt: skip


FORMATS = {"librsf": lambda _nav: _librsf(), "gsdc-derived": lambda _nav: _gsdc_derived(), "ubx": _ubx,
           "gnsslogger": lambda nav: _android("gnsslogger", nav), "device-gnss": lambda nav: _android("device-gnss", nav),
           "rinex": _rinex}  # fmt: skip
