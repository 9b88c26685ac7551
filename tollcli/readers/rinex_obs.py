"""RINEX observation files (2 and 3) read directly, in two passes: :func:`observation_plan` (the first: each system's
code, and whether the file is one to read directly at all) and :func:`iter_observation_rows` (the second: the rows a
block of epochs at a time, memory flat in the file's length). The rows are the ones :func:`tollcli.readers.rinex.observations`
makes of georinex's dataset; where the two could differ the plan is None and georinex reads the file
(:mod:`~tollcli.readers.rinex2_obs`, :mod:`~tollcli.readers.rinex3_obs` say when)."""

from __future__ import annotations

from collections.abc import Iterator

import pandas as pd

from tollcli.readers.rinex2_obs import iter_rinex2_records, rinex2_plan
from tollcli.readers.rinex3_obs import iter_rinex3_records, rinex3_plan
from tollcli.readers.rinex_records import ObservationPlan, block_rows

#: epochs of a RINEX observation file turned into rows at a time by :func:`iter_observation_rows`
BLOCK_EPOCHS = 4_096


def observation_plan(path: str, keep: list | None = None) -> ObservationPlan | None:
    """A first pass over a RINEX 2 or 3 observation file (line by line): its plan, or None where georinex should read
    it. ``keep``: a list that receives the records read (the whole file's, for a caller that reads it whole)."""
    try:
        with open(path, "rb") as fh:
            version = fh.read(9).strip()[:1]
    except OSError:  # (georinex says what is wrong)
        return None
    if version == b"2":
        return rinex2_plan(path, keep)
    if version == b"3":
        return rinex3_plan(path, keep)
    return None


def iter_observation_rows(path: str, plan: ObservationPlan, block_epochs: int | None = None) -> Iterator[pd.DataFrame]:
    """The file's rows (as :func:`observation_rows`), :data:`BLOCK_EPOCHS` epochs at a time, in file order, by the
    ``plan`` its first pass made (:func:`observation_plan`)."""
    records = iter_rinex2_records(path, plan) if plan.version == 2 else iter_rinex3_records(path, plan)
    block: list = []
    for record in records:
        block.append(record)
        if len(block) == (block_epochs or BLOCK_EPOCHS):
            yield block_rows(block, plan)
            block = []
    if block:
        yield block_rows(block, plan)


def observation_rows(path: str) -> pd.DataFrame | None:
    """One row per (epoch, satellite) with a pseudorange — time (GPS time, ns), sv, pr_m, cn0_dbhz, code — sorted by
    time and satellite; None where georinex should read the file. Its blocks (:func:`iter_observation_rows`) joined."""
    records: list = []
    plan = observation_plan(path, keep=records)  # (read once: its records kept)
    return None if plan is None else block_rows(records, plan)
