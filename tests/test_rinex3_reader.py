"""The direct RINEX 3 observation reader (``readers/rinex3_obs.py``) against georinex: the same rows, row for row and
bit for bit — on a real phone's RINEX 3 file, on a real u-blox log's pseudoranges written as RINEX 3.04 (GPS, Galileo
and BeiDou; its header lists GLONASS too), and on synthetic files — and georinex reads whatever the two could read
differently."""

from __future__ import annotations

import pytest
from conftest import shared
from rinex_compare import damaged_copies_read_alike, edited_copy, same_rows
from rinex_compare import georinex_rows as _georinex
from rinex_synth import make_rinex

from tollcli.readers.rinex_obs import observation_rows


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
    assert rows is not None and len(rows) > 900 and same_rows(rows, _georinex(path))


def test_a_real_receivers_three_systems_give_georinexs_rows(tmp_path, walk_rawx):
    """The rtklibexplorer walk's RAWX code pseudoranges (its first 20 s) as RINEX 3.04: GPS and Galileo C1C, BeiDou C6I
    (B3I, chosen: its B1I C2I is empty) with their C/N0, a GLONASS C1C type in the header and no GLONASS satellite."""
    from rinex_multi import write_obs

    rawx = walk_rawx
    write_obs(tmp_path / "walk.obs", rawx[rawx["t_rx_gps_s"] <= rawx["t_rx_gps_s"].min() + 20.0])
    rows = observation_rows(str(tmp_path / "walk.obs"))
    assert rows is not None and set(rows["sv"].str[0]) == {"G", "E", "C"} and set(rows["code"]) == {"C1C", "C6I"}
    assert same_rows(rows, _georinex(tmp_path / "walk.obs"))


def test_line_endings_and_a_synthetic_file(synthetic, tmp_path):
    rows = observation_rows(str(synthetic))
    assert rows is not None and same_rows(rows, _georinex(synthetic))
    crlf = tmp_path / "crlf.24o"
    crlf.write_bytes(synthetic.read_bytes().replace(b"\n", b"\r\n"))
    assert same_rows(observation_rows(str(crlf)), rows)


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
    path = edited_copy(synthetic, tmp_path, edits[case])
    assert observation_rows(path) is None


def test_damaged_copies_of_a_real_file_are_read_as_georinex_reads_them(tmp_path, walk_rawx):
    """Twelve copies of the real walk's first 3 s as RINEX 3.04 (13 epochs), each with bytes changed, cut
    or added in its header or records: the direct reader gives georinex's rows, or leaves the file to georinex."""
    from rinex_multi import write_obs

    rawx = walk_rawx
    write_obs(tmp_path / "walk.obs", rawx[rawx["t_rx_gps_s"] <= rawx["t_rx_gps_s"].min() + 3.0])
    read_alike = damaged_copies_read_alike((tmp_path / "walk.obs").read_bytes(), tmp_path, 12, 0.5, b"0123456789 .-+>GREC\n")
    assert read_alike >= 4  # (most damaged copies still read)
