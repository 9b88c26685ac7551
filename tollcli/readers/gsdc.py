"""The Google Smartphone Decimeter Challenge "derived" CSV, read and checked.

One row per satellite-signal and epoch (``millisSinceGpsEpoch``) with the
satellite's ECEF position, clock bias and modelled delays; positions and RAIM
measurements are made from it in :mod:`tollcli.gnss.gsdc_positions`.
"""

from __future__ import annotations

import pandas as pd

from tollcli.errors import DataError

ANDROID_CONSTELLATION = {1: "GPS", 2: "SBAS", 3: "GLONASS", 4: "QZSS", 5: "BeiDou", 6: "Galileo", 7: "NavIC"}
REQUIRED = ("millisSinceGpsEpoch", "constellationType", "svid", "signalType", "xSatPosM", "ySatPosM", "zSatPosM",
            "satClkBiasM", "rawPrM", "rawPrUncM", "isrbM", "ionoDelayM", "tropoDelayM")  # fmt: skip


def read_gsdc_derived(path) -> pd.DataFrame:
    """The derived CSV with the columns the WLS needs, checked."""
    try:
        table = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not a readable CSV ({exc})") from None
    missing = [c for c in REQUIRED if c not in table.columns]
    if missing:
        raise DataError(f"{path}: not a GSDC derived file, missing columns {', '.join(missing)}")
    return table
