"""The direct RINEX 3 observation reader (``readers/rinex3_obs.py``) against georinex: the same rows, row for row and
bit for bit — on a real phone's RINEX 3 file, on a real u-blox log's pseudoranges written as RINEX 3.04 (GPS, Galileo
and BeiDou; its header lists GLONASS too), and on synthetic files — and georinex reads whatever the two could read
differently."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from conftest import shared
from rinex_synth import make_rinex

from tollcli.readers.rinex import load_rinex, observations
from tollcli.readers.rinex_obs import observation_rows


def _georinex(path) -> pd.DataFrame:
    return observations(load_rinex(str(path), "observation"))


def _same(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    if list(a.columns) != list(b.columns) or len(a) != len(b) or dict(a.dtypes) != dict(b.dtypes):
        return False
    return all(np.array_equal(a[c].to_numpy(), b[c].to_numpy(), equal_nan=True) if a[c].dtype.kind == "f" else
               (a[c].to_numpy() == b[c].to_numpy()).all() for c in a.columns)  # fmt: skip


@pytest.fixture(scope="module")
def walk_rawx():
    """The rtklibexplorer walk's RAWX code pseudoranges, decoded once."""
    from tollcli.gnss.ubx_measurements import rawx_measurements
    from tollcli.readers.ubx import read_ubx

    return rawx_measurements(read_ubx(str(shared("rtklibexplorer", "gnss_1730.ubx"))))


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    obs, _, _ = make_rinex(tmp_path_factory.mktemp("rinex"), n_epochs=20, noise_m=0.5, seed=7)
    return obs


def test_a_real_phones_rinex_3_file_gives_georinexs_rows():
    path = shared("android", "pixel6.23o")
    rows = observation_rows(str(path))
    assert rows is not None and len(rows) > 900 and _same(rows, _georinex(path))


def test_a_real_receivers_three_systems_give_georinexs_rows(tmp_path, walk_rawx):
    """The rtklibexplorer walk's RAWX code pseudoranges (its first 20 s) as RINEX 3.04: GPS and Galileo C1C, BeiDou C6I
    (B3I, chosen: its B1I C2I is empty) with their C/N0, a GLONASS C1C type in the header and no GLONASS satellite."""
    from rinex_multi import write_obs

    rawx = walk_rawx
    write_obs(tmp_path / "walk.obs", rawx[rawx["t_rx_gps_s"] <= rawx["t_rx_gps_s"].min() + 20.0])
    rows = observation_rows(str(tmp_path / "walk.obs"))
    assert rows is not None and set(rows["sv"].str[0]) == {"G", "E", "C"} and set(rows["code"]) == {"C1C", "C6I"}
    assert _same(rows, _georinex(tmp_path / "walk.obs"))


def test_line_endings_and_a_synthetic_file(synthetic, tmp_path):
    rows = observation_rows(str(synthetic))
    assert rows is not None and _same(rows, _georinex(synthetic))
    crlf = tmp_path / "crlf.24o"
    crlf.write_bytes(synthetic.read_bytes().replace(b"\n", b"\r\n"))
    assert _same(observation_rows(str(crlf)), rows)


def _edited(synthetic, tmp_path, edit) -> str:
    lines = synthetic.read_text().splitlines(keepends=True)
    body = next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1
    out = tmp_path / "edited.24o"
    out.write_text("".join(edit(lines, body)))
    return str(out)


@pytest.mark.parametrize("case", ["epoch twice", "satellite twice", "not a number", "hash", "cut short", "non-ascii",
                                  "no time system", "version unreadable"])
def test_what_the_two_could_read_differently_is_left_to_georinex(synthetic, tmp_path, case):
    """Each of these files is read by georinex (None from the direct reader); the positions still come (or georinex's
    own error)."""
    def epoch_twice(lines, body):
        second = next(i for i in range(body + 1, len(lines)) if lines[i].startswith(">"))
        return lines[:second] + lines[body:second] + lines[second:]

    def satellite_twice(lines, body):
        return lines[: body + 2] + [lines[body + 1]] + lines[body + 2 :]

    def numbers(lines, body, text):
        line = lines[body + 1]
        return lines[: body + 1] + [line[:3] + text + line[3 + len(text) :]] + lines[body + 2 :]

    edits = {"epoch twice": epoch_twice, "satellite twice": satellite_twice,
             "not a number": lambda lines, body: numbers(lines, body, "  2x234567.123"),
             "hash": lambda lines, body: numbers(lines, body, "  #"),
             "cut short": lambda lines, body: lines[:-2],  # the last epoch's last satellites missing
             "non-ascii": lambda lines, body: [lines[0]] + ["é" + lines[1][1:]] + lines[2:],
             "no time system": lambda lines, body: [ln for ln in lines if "TIME OF FIRST OBS" not in ln],
             "version unreadable": lambda lines, body: ["     3..4" + lines[0][9:]] + lines[1:]}  # fmt: skip
    path = _edited(synthetic, tmp_path, edits[case])
    assert observation_rows(path) is None


def test_damaged_copies_of_a_real_file_are_read_as_georinex_reads_them(tmp_path, walk_rawx):
    """Twelve copies of the real walk's first 3 s as RINEX 3.04 (13 epochs), each with bytes changed, cut
    or added in its header or records: the direct reader gives georinex's rows, or leaves the file to georinex."""
    import random

    from rinex_multi import write_obs

    from tollcli.errors import TollError

    rawx = walk_rawx
    write_obs(tmp_path / "walk.obs", rawx[rawx["t_rx_gps_s"] <= rawx["t_rx_gps_s"].min() + 3.0])
    clean = (tmp_path / "walk.obs").read_bytes()
    header = clean.index(b"END OF HEADER")
    rng = random.Random(8)
    read_alike = 0
    for k in range(12):
        data = bytearray(clean)
        for _ in range(rng.randint(1, 4)):
            at = rng.randrange(header + 80) if rng.random() < 0.5 else rng.randrange(len(data))
            change = rng.random()
            if change < 0.5:
                data[at] = rng.choice(b"0123456789 .-+>GREC\n")
            elif change < 0.75:
                del data[at : at + rng.randint(1, 30)]
            else:
                data[at:at] = bytes(rng.choice(b"0123456789 .\n") for _ in range(rng.randint(1, 16)))
        path = tmp_path / f"damaged-{k}.obs"
        path.write_bytes(bytes(data))
        rows = observation_rows(str(path))
        if rows is None:
            continue
        try:
            reference = _georinex(path)
        except TollError as exc:
            raise AssertionError(f"copy {k}: read directly, refused by georinex ({exc})") from None
        assert _same(rows, reference), k
        read_alike += 1
    assert read_alike >= 4  # (most damaged copies still read)
