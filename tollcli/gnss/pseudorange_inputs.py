"""Pseudorange inputs by kind: the GSDC derived CSV and RINEX 3 obs + nav → (epochs, measurements)."""

from __future__ import annotations

import pandas as pd

from tollcli.errors import UsageError
from tollcli.gnss.measurements import Measurements
from tollcli.gnss.sigma_models import NominalModel


def pseudorange_epochs(log: str, kind: str, nav: str | None, sigma_model: str, sigma_m: float,
                       nominal: NominalModel) -> tuple[pd.DataFrame, Measurements]:  # fmt: skip
    """WLS epochs and RAIM measurements for a ``gsdc-derived`` or ``rinex`` log."""
    if kind == "gsdc-derived":
        from tollcli.gnss.gsdc_positions import gsdc_epochs
        from tollcli.readers.gsdc import read_gsdc_derived

        return gsdc_epochs(read_gsdc_derived(log), sigma_model, sigma_m, nominal)
    if kind == "rinex":
        from tollcli.gnss.rinex_positions import rinex_epochs

        if nav is None:
            raise UsageError("RINEX input needs --nav NAVFILE (broadcast ephemerides)")
        return rinex_epochs(log, nav, sigma_model, sigma_m, nominal)
    raise UsageError(f"{log}: {kind} is not a pseudorange format")
