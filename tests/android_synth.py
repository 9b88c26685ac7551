"""An Android phone simulated on real broadcast ephemerides: GnssLogger ``Raw`` records (text) or the same fields as a
GSDC ``device_gnss.csv``, from the receiver of :func:`ubx_synth.receiver_epochs`.

Each epoch's pseudorange ρ is written as Android states it (its ``GnssMeasurement`` documentation): the receiver's
GPS time t_rx = TimeNanos − FullBiasNanos − BiasNanos, and the satellite's transmit time ``ReceivedSvTimeNanos`` =
t_rx (in the week) − ⌊ρ/c⌋ ns, the sub-nanosecond rest in ``TimeOffsetNanos``; so ρ = (t_rx − t_tx) · c comes back to
the bit of a nanosecond. GPS and Galileo L1/E1 with their time of week decoded. Nothing here uses the reader under test.
"""

from __future__ import annotations

import numpy as np
from ubx_synth import L1, receiver_epochs

C = 299_792_458.0
WEEK_NS = 604_800 * 10**9
#: the fields written, in the order of a GnssLogger ``# Raw,`` header (a subset of the app's, all a pseudorange needs)
FIELDS = ("utcTimeMillis", "TimeNanos", "LeapSecond", "FullBiasNanos", "BiasNanos", "Svid", "TimeOffsetNanos", "State",
          "ReceivedSvTimeNanos", "ReceivedSvTimeUncertaintyNanos", "Cn0DbHz", "PseudorangeRateMetersPerSecond",
          "PseudorangeRateUncertaintyMetersPerSecond", "CarrierFrequencyHz", "ConstellationType", "HardwareClockDiscontinuityCount")  # fmt: skip
#: Android's constellation types and the tracking states of a decoded time of week (code lock, TOW decoded; Galileo
#: also E1BC code lock)
CONSTELLATION = {"G": 1, "E": 6}
STATE = {"G": 1 | 8, "E": 1 | 8 | 1024}


def raw_records(eph_table, t0_gps_s: float, n_epochs: int, lat_deg: float, lon_deg: float, h_m: float, **receiver) -> list[list]:
    """One list of :data:`FIELDS` values per satellite and epoch."""
    rows = []
    for k, (t, svs, pr, dop) in enumerate(receiver_epochs(eph_table, t0_gps_s, n_epochs, lat_deg, lon_deg, h_m, **receiver)):
        time_nanos = (k + 1000) * 10**9  # the phone's hardware clock
        gps_ns = int(round(t * 1e9))
        full_bias = time_nanos - gps_ns
        flight_ns = pr / C * 1e9
        whole = np.floor(flight_ns).astype(np.int64)
        for sv, w, rest, d in zip(svs, whole.tolist(), (flight_ns - whole).tolist(), dop.tolist()):
            rows.append([int(round(t * 1000)) - 18_000 + 315_964_800_000, time_nanos, 18, full_bias, 0.0, int(sv[1:]), repr(rest),
                         STATE[sv[0]], gps_ns % WEEK_NS - w, 10.0, 42.0, repr(-d * C / L1), 0.1, L1, CONSTELLATION[sv[0]], 0])  # fmt: skip
    return rows


def gnsslogger_text(records: list[list], lat_deg: float, lon_deg: float) -> str:
    """A GnssLogger file of ``records`` (:func:`raw_records`): its comment header (with the ``# Raw,`` line), then a
    ``Raw`` line per record and a ``Fix`` line before each epoch's (records the reader passes over)."""
    lines = ["# ", "# Header Description:", "# ", "# Version: v3.0.5.6 Platform: 13 Manufacturer: Google Model: Pixel 6",
             "# ", "# Raw," + ",".join(FIELDS), "# ", "# Fix,Provider,LatitudeDegrees,LongitudeDegrees", "# "]  # fmt: skip
    last = None
    for row in records:
        if row[1] != last:
            lines.append(f"Fix,GPS,{lat_deg},{lon_deg}")
            last = row[1]
        lines.append("Raw," + ",".join(str(v) for v in row))
    return "\n".join(lines) + "\n"


def device_gnss_csv(records: list[list]) -> str:
    """``records`` (:func:`raw_records`) as a ``device_gnss.csv`` (no satellite columns: its orbits come from
    ``--nav``)."""
    return "\n".join([",".join(FIELDS)] + [",".join(str(v) for v in row) for row in records]) + "\n"
