"""The direct RINEX observation readers held against georinex (test helper): the rows of each, compared bit for bit,
and damaged copies of a file."""

from __future__ import annotations

import logging
import random
from pathlib import Path

import numpy as np
import pandas as pd

from tollcli.readers.rinex import load_rinex, observations
from tollcli.readers.rinex_obs import observation_rows


def georinex_rows(path, fast: bool = True) -> pd.DataFrame:
    """The rows of georinex's dataset of ``path`` (``fast=False``: georinex's careful reading, which counts the
    epochs first)."""
    if fast:
        return observations(load_rinex(str(path), "observation"))
    import georinex

    return observations(georinex.load(str(path), use={"G", "E", "R", "C"}, fast=False))


def same_rows(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    """The same columns, types and values (NaN where NaN)."""
    if list(a.columns) != list(b.columns) or len(a) != len(b) or dict(a.dtypes) != dict(b.dtypes):
        return False
    return all(np.array_equal(a[c].to_numpy(), b[c].to_numpy(), equal_nan=True) if a[c].dtype.kind == "f" else
               (a[c].to_numpy() == b[c].to_numpy()).all() for c in a.columns)  # fmt: skip


def edited_copy(path: Path, folder: Path, edit) -> str:
    """A copy of ``path`` in ``folder`` with ``edit(lines, body)`` applied (``body``: the first record line's index)."""
    lines = path.read_text().splitlines(keepends=True)
    body = next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1
    out = folder / f"edited{path.suffix}"
    out.write_text("".join(edit(lines, body)))
    return str(out)


def damaged_copies_read_alike(clean: bytes, folder: Path, copies: int, header_share: float, letters: bytes, seed: int = 8) -> int:
    """``copies`` copies of ``clean`` (a RINEX observation file) each with 1–4 bytes changed (to one of ``letters``),
    runs of bytes cut or digits added — a share ``header_share`` of them in its header — asserting that the direct
    reader gives georinex's rows or leaves the file to georinex; returns how many it read."""
    from tollcli.errors import TollError

    header = clean.index(b"END OF HEADER")
    rng = random.Random(seed)
    read_alike = 0
    logging.disable(logging.ERROR)  # (georinex logs what it makes of a damaged header)
    try:
        for k in range(copies):
            data = bytearray(clean)
            for _ in range(rng.randint(1, 4)):
                at = rng.randrange(header + 80) if rng.random() < header_share else rng.randrange(len(data))
                change = rng.random()
                if change < 0.5:
                    data[at] = rng.choice(letters)
                elif change < 0.75:
                    del data[at : at + rng.randint(1, 30)]
                else:
                    data[at:at] = bytes(rng.choice(b"0123456789 .\n") for _ in range(rng.randint(1, 16)))
            path = folder / f"damaged-{k}.obs"
            path.write_bytes(bytes(data))
            rows = observation_rows(str(path))
            if rows is None:
                continue
            try:
                reference = georinex_rows(path)
            except TollError as exc:
                raise AssertionError(f"copy {k}: read directly, refused by georinex ({exc})") from None
            assert same_rows(rows, reference), k
            read_alike += 1
    finally:
        logging.disable(logging.NOTSET)
    return read_alike
