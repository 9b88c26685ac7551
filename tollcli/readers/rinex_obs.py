"""RINEX observation files (2 and 3) read directly, in two passes: :func:`observation_plan` (the first: each system's
code, and whether the file is one to read directly at all) and :func:`iter_observation_rows` (the second: the rows a
block of epochs at a time, memory flat in the file's length). The rows are the ones :func:`tollcli.readers.rinex.observations`
makes of georinex's dataset; where the two could differ the plan is None and georinex reads the file
(:mod:`~tollcli.readers.rinex2_obs`, :mod:`~tollcli.readers.rinex3_obs` say when)."""

from __future__ import annotations

from collections.abc import Iterator

import pandas as pd

from tollcli.readers import rinex2_obs, rinex3_obs
from tollcli.readers.rinex_records import ObservationPlan, block_rows, file_records, first_pass

#: each version's header and records (:func:`~tollcli.readers.rinex_records.first_pass`,
#: :func:`~tollcli.readers.rinex_records.file_records`)
VERSIONS = {2: rinex2_obs, 3: rinex3_obs}
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
    reader = VERSIONS.get(int(version)) if version.isdigit() else None
    return None if reader is None else first_pass(path, int(version), reader.header_of, reader.records_of, keep)


def iter_observation_rows(path: str, plan: ObservationPlan, block_epochs: int | None = None) -> Iterator[pd.DataFrame]:
    """The file's rows (as :func:`observation_rows`), :data:`BLOCK_EPOCHS` epochs at a time, in file order, by the
    ``plan`` its first pass made (:func:`observation_plan`)."""
    reader = VERSIONS[plan.version]
    records = file_records(path, reader.header_of, reader.records_of)
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
