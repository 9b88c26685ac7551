"""Pseudorange inputs by kind → (epochs, measurements).

* ``gsdc-derived``: the GSDC 2021 derived CSV (Google's satellite positions);
* ``rinex``: a RINEX 3 observation file with ``--nav`` (broadcast ephemerides);
* ``gnsslogger``: an Android GnssLogger text file (``Raw`` records) with ``--nav``;
* ``device-gnss``: a GSDC 2022/2023 ``device_gnss.csv`` — its own satellite columns, or ``--nav``'s orbits;
* ``ubx``: a u-blox log with ``RXM-RAWX`` — satellites from its own ``RXM-SFRBX`` subframes, or ``--nav``;
* ``librsf``: a libRSF text log (smartLoc): corrected pseudoranges with their satellites' positions.
"""

from __future__ import annotations

import pandas as pd

from tollcli.errors import DataError, UsageError
from tollcli.gnss.measurements import Measurements
from tollcli.gnss.sigma_models import NominalModel

PSEUDORANGE_FORMATS = ("gsdc-derived", "rinex", "gnsslogger", "device-gnss", "ubx", "librsf")


class NoOrbitsError(DataError):
    """A pseudorange log whose satellites' orbits are neither in it nor given (``--nav``)."""


def pseudorange_epochs(log: str, kind: str, nav: str | list[str] | None, sigma_model: str, sigma_m: float,
                       nominal: NominalModel, strict: bool = False) -> tuple[pd.DataFrame, Measurements]:  # fmt: skip
    """WLS epochs (with Doppler velocities where the input has rates) and RAIM measurements of a pseudorange log."""
    if kind == "gsdc-derived":
        from tollcli.gnss.gsdc_positions import gsdc_epochs
        from tollcli.readers.gsdc import read_gsdc_derived

        derived = read_gsdc_derived(log, strict)
        epochs, meas = gsdc_epochs(derived, sigma_model, sigma_m, nominal)
        epochs.attrs["skipped_lines"] = derived.attrs["skipped_lines"]
        return epochs, meas
    if kind == "rinex":
        from tollcli.gnss.rinex_positions import rinex_epochs

        if is_rinex_navigation(log):
            raise UsageError(f"{log}: a RINEX navigation file (satellite orbits), not observations: give it as --nav beside the "
                             "observation file")  # fmt: skip
        if nav is None:
            raise UsageError(f"{log}: a RINEX observation file carries no satellite orbits: give --nav NAVFILE (RINEX 2 or 3 broadcast ephemerides)")
        return rinex_epochs(log, nav, sigma_model, sigma_m, nominal)
    if kind == "librsf":
        from tollcli.gnss.librsf_positions import librsf_epochs
        from tollcli.readers.librsf import read_librsf

        try:
            return librsf_epochs(read_librsf(log, strict), sigma_model, sigma_m, nominal)
        except DataError as exc:
            raise DataError(exc.args[0] if exc.args[0].startswith(log) else f"{log}: {exc}") from None
    if kind in ("gnsslogger", "device-gnss", "ubx"):
        return _raw_epochs(log, kind, nav, sigma_model, sigma_m, nominal, strict)
    raise UsageError(f"{log}: {kind} is not a pseudorange format")


def ubx_orbits(log: str, ubx, ephemerides: pd.DataFrame | None) -> pd.DataFrame:
    """The orbits a u-blox log's pseudoranges are solved with: ``ephemerides`` (``--nav``), else those of its own
    RXM-SFRBX. Raises DataError for a log without RXM-RAWX measurements, NoOrbitsError for one without either orbits."""
    from tollcli.gnss.ubx_measurements import sfrbx_ephemerides

    heads = ubx.rawx_heads
    if ubx.rawx.empty and (heads is None or not (heads["numMeas"].to_numpy() > 0).any()):
        raise DataError(f"{log}: no RXM-RAWX measurements in the UBX log (the receiver was not set to output raw data)")
    if ephemerides is None:
        ephemerides = sfrbx_ephemerides(ubx)
        if ephemerides.empty:
            raise NoOrbitsError(f"{log}: no complete GPS, Galileo, BeiDou or GLONASS ephemeris in the log's RXM-SFRBX navigation data: give --nav NAVFILE")
    return ephemerides


def navigation_of(nav: str | list[str] | None):
    """The ephemerides and ionosphere coefficients of ``--nav`` (one file or several), or (None, None)."""
    if nav is None:
        return None, None
    from tollcli.gnss.satellite_states import load_navigation

    return load_navigation(nav)


def is_rinex_navigation(path: str) -> bool:
    """Whether a RINEX file's first line says it holds navigation data (type N, G, C, … in column 21), not observations."""
    try:
        with open(path, "rb") as f:
            first = f.readline(82).decode("ascii", "replace")
    except OSError:
        return False
    return "RINEX VERSION / TYPE" in first[60:] and first[20:21] not in ("O", "")


def _raw_epochs(log: str, kind: str, nav: str | list[str] | None, sigma_model: str, sigma_m: float, nominal: NominalModel,
                strict: bool) -> tuple[pd.DataFrame, Measurements]:  # fmt: skip
    from tollcli.gnss.raw_positions import (
        raw_epochs,
        with_broadcast_satellites,
        with_device_gnss_satellites,
    )

    ephemerides, iono = navigation_of(nav)  # one file or several
    if kind == "gnsslogger":
        from tollcli.gnss.android_raw import raw_pseudoranges
        from tollcli.readers.gnsslogger import read_gnsslogger

        if ephemerides is None:
            raise UsageError(f"{log}: a GnssLogger file carries no satellite orbits: give --nav NAVFILE (RINEX 2 or 3)")
        read = read_gnsslogger(log, strict)
        skipped = read.n_malformed + read.raw.attrs.get("skipped_lines", 0)
        m = with_broadcast_satellites(raw_pseudoranges(read.raw), ephemerides)
    elif kind == "device-gnss":
        from tollcli.gnss.android_raw import raw_pseudoranges
        from tollcli.readers.gnsslogger import read_device_gnss

        device = read_device_gnss(log, strict)
        skipped = device.attrs["skipped_lines"]
        m = raw_pseudoranges(device)
        m = with_device_gnss_satellites(m, device) if ephemerides is None else with_broadcast_satellites(m, ephemerides)
    else:
        from tollcli.gnss.ubx_measurements import rawx_measurements
        from tollcli.readers.ubx import read_ubx

        ubx = read_ubx(log, strict)
        skipped = ubx.n_bad  # damaged frames: a bad checksum, cut short, a length its counts do not give, a date that is none
        ephemerides = ubx_orbits(log, ubx, ephemerides)
        m = with_broadcast_satellites(rawx_measurements(ubx), ephemerides)
    try:
        epochs, meas = raw_epochs(m, sigma_model, sigma_m, nominal, iono_coeffs=iono)
    except DataError as exc:
        raise DataError(f"{log}: {exc}") from None
    epochs.attrs["skipped_lines"] = int(skipped)
    if kind == "ubx":
        from tollcli.gnss.ubx_measurements import with_receiver_solution

        epochs = with_receiver_solution(epochs, ubx.pvt)  # the receiver's own NAV-PVT beside ours, for comparison
    return epochs, meas
