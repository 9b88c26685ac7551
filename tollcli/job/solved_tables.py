"""A pseudorange log's epoch and satellite tables, for ``tollcli epochs``: what the log's own measurements solve to.

A navigation log (NMEA, u-blox NAV, gpsd JSON) carries the receiver's positions, and ``epochs`` decodes them. A
pseudorange log (RINEX, GnssLogger, GSDC, u-blox RAWX, libRSF) carries none of its own (or not only): its epochs are
the snapshot weighted least squares of each epoch's pseudoranges (:mod:`tollcli.gnss.pseudorange_inputs`) — the
positions ``tollcli integrity --positioning snapshot`` vouches for, without their verdicts — and its satellite table
has a row per pseudorange an epoch used: the satellite, its angles, C/N0, the corrected pseudorange, the error model's σ
and the pre-fit residual at the solution.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements
from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
from tollcli.gnss.sigma_models import NominalModel
from tollcli.readers.navigation import iter_navigation_tables

def receiver_fix_tables(run, strict: bool, stats) -> Iterator:
    """The epoch and satellite tables of a u-blox log's own fixes (its NAV messages), chunk by chunk: what ``epochs``
    gives a RAWX log without the orbits to solve it (the log's replay, already read: ``run`` a
    :class:`~tollcli.io.log_run.LogRun`; its errors and ``stats`` name the log, not the replay)."""
    with run.named_errors():
        yield from iter_navigation_tables(run.source(), "ubx-nav", strict=strict, stats=stats)
    stats.source = run.name


#: the satellite table's columns
SATELLITE_COLUMNS = ("epoch", "time_utc", "sv", "elev_deg", "azim_deg", "cn0_dbhz", "pr_m", "sigma_m", "prefit_residual_m",
                     "clock_group")  # fmt: skip


def solved_tables(path: str, kind: str, nav: str | tuple[str, ...] | None, strict: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The epoch table (one row per epoch: the snapshot WLS position, its clock, the measurements it used, and what
    the log says besides — odometry, Doppler speed, the receiver's own fix) and the satellite table of a pseudorange
    log ``path`` of format ``kind``. ``attrs['skipped_lines']``: the malformed lines the reader passed over."""
    epochs, meas = pseudorange_epochs(path, kind, nav, "nominal", 5.0, NominalModel(), strict)
    return epochs, satellite_table(epochs, meas)


def satellite_table(epochs: pd.DataFrame, meas: Measurements) -> pd.DataFrame:
    """One row per measurement an epoch used, in epoch order and the epoch's slot order."""
    row, slot = np.nonzero(meas.mask)
    los_enu = -meas.H[row, slot, :3]  # (the observation matrix's first three columns: minus the line of sight)
    up = np.clip(los_enu[:, 2], -1.0, 1.0)

    def at(values) -> np.ndarray:
        return np.full(row.size, np.nan) if values is None else np.asarray(values, float)[row, slot]

    table = pd.DataFrame(
        {
            "epoch": epochs["epoch"].to_numpy()[row],
            "time_utc": epochs["time_utc"].take(row).reset_index(drop=True),
            "sv": np.asarray(meas.sv)[row, slot],
            "elev_deg": np.degrees(np.arcsin(up)),
            "azim_deg": np.degrees(np.arctan2(los_enu[:, 0], los_enu[:, 1])) % 360.0,
            "cn0_dbhz": at(meas.cn0_dbhz),
            "pr_m": at(meas.pr_m),
            "sigma_m": at(meas.sigma_m),
            "prefit_residual_m": at(meas.dy_m),
            "clock_group": (np.zeros(row.size, np.int64) if meas.clock_index is None else np.asarray(meas.clock_index)[row, slot]),
        }
    )
    return table[list(SATELLITE_COLUMNS)]
