"""The direct RINEX 2 observation reader (``readers/rinex2_obs.py``) against georinex: the same rows, row for row and
bit for bit — on a real u-blox receiver's log turned into RINEX 2.11 by RTKLIB's ``convbin`` (GPS, Galileo and SBAS
satellites, eight observation types on two lines a satellite, satellite lists continued), on synthetic files and on
damaged copies — and georinex reads whatever the two could read differently."""

from __future__ import annotations

import logging
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest
from conftest import shared
from rinex_compare import damaged_copies_read_alike, edited_copy, same_rows
from rinex_compare import georinex_rows as _georinex
from rinex_synth import make_rinex

from tollcli.readers.rinex2_obs import rinex2_plan
from tollcli.readers.rinex3_obs import rinex3_plan
from tollcli.readers.rinex_obs import iter_observation_rows, observation_plan, observation_rows

CONVBIN = shutil.which("convbin")
needs_convbin = pytest.mark.skipif(CONVBIN is None, reason="RTKLIB's convbin not installed (Debian: apt-get install rtklib)")


@pytest.fixture(scope="module")
def walk_rinex2(tmp_path_factory):
    """The rtklibexplorer walk's first ``seconds`` as RINEX 2.11 observations (and GPS navigation), by convbin."""
    folder = tmp_path_factory.mktemp("walk2")
    ubx = shared("rtklibexplorer", "gnss_1730.ubx")

    def convert(seconds: float | None = None, options: tuple[str, ...] = ("-v", "2.11", "-od", "-os")) -> tuple[str, str]:
        name = f"walk-{seconds or 'all'}{''.join(options)}"
        minute, second = divmod(int(39.7 + (seconds or 0.0)), 60)
        end = [] if seconds is None else ["-te", "2025/08/28", f"17:{30 + minute:02d}:{second:02d}"]
        subprocess.run([CONVBIN, "-r", "ubx", *options, *end, "-o", str(folder / f"{name}.obs"), "-n", str(folder / f"{name}.nav"),
                        str(ubx)], check=True, capture_output=True)  # fmt: skip
        return str(folder / f"{name}.obs"), str(folder / f"{name}.nav")

    return convert


@needs_convbin
def test_a_real_receivers_rinex_2_file_gives_georinexs_rows(walk_rinex2):
    """convbin's RINEX 2.11 of the whole walk (536 epochs): GPS and Galileo C1 with S1, SBAS satellites passed over;
    read a block of 37 epochs at a time, the same rows."""
    obs, _ = walk_rinex2()
    head = open(obs).read(2000)
    assert head.startswith("     2.11") and "     8    C1    L1    D1    S1    C2    L2    D2    S2" in head
    rows = observation_rows(obs)
    assert rows is not None and len(rows) > 5000 and set(rows["sv"].str[0]) == {"G", "E"} and set(rows["code"]) == {"C1"}
    assert same_rows(rows, _georinex(obs))
    plan = observation_plan(obs)
    assert plan.version == 2 and rinex3_plan(obs) is None
    parts = list(iter_observation_rows(obs, plan, 37))
    assert len(parts) == 15 and same_rows(pd.concat(parts, ignore_index=True), rows)


@needs_convbin
@pytest.mark.parametrize("options", [("-v", "2.10", "-f", "1", "-od", "-os"), ("-v", "2.12", "-f", "3", "-od", "-os", "-ol", "-oi")])
def test_other_rinex_2_layouts_give_georinexs_rows(walk_rinex2, options):
    """convbin's RINEX 2.10 of one frequency (C1 L1 D1 S1: a satellite's values on one short line; georinex then keeps
    the times to the millisecond, .747 where the file says .7479990) and RINEX 2.12 of three (12 types, their list
    continued on a second header line, three lines a satellite)."""
    obs, _ = walk_rinex2(30.0, options)
    rows = observation_rows(obs)
    assert rows is not None and len(rows) > 500 and same_rows(rows, _georinex(obs))
    if "2.10" in options:
        assert (rows["time"].dt.microsecond % 1000 == 0).all() and (rows["time"].dt.microsecond > 0).any()


@needs_convbin
def test_a_real_receivers_rinex_2_file_gives_the_positions_georinex_gives(walk_rinex2, monkeypatch):
    """The walk's first 20 s, solved with convbin's GPS navigation file (of the whole walk): the same epochs and
    measurements whether its rows come from this reader or from georinex."""
    from tollcli.gnss import rinex_positions

    obs, nav = walk_rinex2(20.0)[0], walk_rinex2()[1]  # (the navigation data of the whole walk)
    direct_epochs, direct_meas = rinex_positions.rinex_epochs(obs, nav)
    monkeypatch.setattr(rinex_positions, "observation_rows", lambda path: None)
    epochs, meas = rinex_positions.rinex_epochs(obs, nav)
    assert direct_epochs["lat_deg"].notna().sum() > 60
    pd.testing.assert_frame_equal(direct_epochs, epochs)
    assert np.array_equal(direct_meas.H, meas.H, equal_nan=True)
    assert np.array_equal(direct_meas.dy_m, meas.dy_m, equal_nan=True)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    obs, _, _ = make_rinex(tmp_path_factory.mktemp("rinex2"), n_epochs=20, noise_m=0.5, seed=7, version=2)
    return obs


def test_a_synthetic_file_and_its_line_endings(synthetic, tmp_path):
    rows = observation_rows(str(synthetic))
    assert rows is not None and rinex2_plan(str(synthetic)) is not None and same_rows(rows, _georinex(synthetic))
    crlf = tmp_path / "crlf.24o"
    crlf.write_bytes(synthetic.read_bytes().replace(b"\n", b"\r\n"))
    assert same_rows(observation_rows(str(crlf)), rows)


def _second_epoch(lines, body) -> int:
    return next(i for i in range(body + 1, len(lines)) if lines[i][:3] == lines[body][:3] and lines[i][28:29] == "0")


def _before_second(new_lines):
    """An edit: ``new_lines`` put before the second epoch."""
    def edit(lines, body):
        second = _second_epoch(lines, body)
        return lines[:second] + new_lines(lines, body) + lines[second:]

    return edit


def _first_epoch_line(at: int, text: str, end: int | None = None):
    """An edit: the first epoch line's columns ``at``… (to ``end``, else as many as ``text``) replaced by ``text``."""
    def edit(lines, body):
        line = lines[body]
        return lines[:body] + [line[:at] + text + line[at + len(text) if end is None else end :]] + lines[body + 1 :]

    return edit


def _first_header_line(at: int, text: str):
    return lambda lines, body: [lines[0][:at] + text + lines[0][at + len(text) :]] + lines[1:]


def _without(label: str):
    return lambda lines, body: [ln for ln in lines if label not in ln]


#: edits georinex reads as this reader does (the rows must be the same)
READ_ALIKE = {
    "an event flag 4 and its comment": _before_second(lambda lines, body: [" 24  5  6  8  0  0.5000000  4  1\n",
                                                                          f"{'a comment':<60}COMMENT\n"]),
    "a blank line between epochs": _before_second(lambda lines, body: ["\n"]),
    "a satellite's blank system letter (GPS)": _first_epoch_line(56, " "),
    "the last epoch cut short": lambda lines, body: lines[:-2],
    "a value blank": lambda lines, body: lines[: body + 2] + [" " * 14 + lines[body + 2][14:]] + lines[body + 3 :],
    "a GPS file (its Galileo satellites not read)": _first_header_line(40, "G"),
    "power failure (flag 1)": _first_epoch_line(28, "1"),
    "an epoch line cut at its flag (passed over)": _first_epoch_line(28, "\n", end=len("\n") * 10**6),
}
#: edits this reader leaves to georinex (None), which reads them or says what is wrong
LEFT_TO_GEORINEX = {
    "an epoch time twice": _before_second(lambda lines, body: lines[body : _second_epoch(lines, body)]),
    "a satellite twice": lambda lines, body: _first_epoch_line(35, lines[body][32:35])(lines, body),
    "satellite number 0": _first_epoch_line(33, "00"),
    "satellite number 37": _first_epoch_line(33, "37"),
    "not a number": lambda lines, body: lines[: body + 2] + ["  2x234567.123" + lines[body + 2][14:]] + lines[body + 3 :],
    "an external event (flag 5)": _first_epoch_line(28, "5"),
    "cycle slips (flag 6)": _first_epoch_line(28, "6"),
    "an epoch line cut short of its flag": _first_epoch_line(27, "\n", end=len("\n") * 10**6),
    "blank file system": _first_header_line(40, " "),
    "mixed without TIME OF FIRST OBS": _without("TIME OF FIRST OBS"),
    "types not as many as said": lambda lines, body: [ln.replace("     2    C1", "     3    C1") for ln in lines],
    "a type twice": lambda lines, body: [ln.replace("     2    C1    S1", "     2    C1    C1") for ln in lines],
    "no END OF HEADER": _without("END OF HEADER"),
    "version unreadable": _first_header_line(0, "     2..1"),
    "non-ascii": _first_epoch_line(0, "é"),
}
#: edits whose rows are the clean file's (the edit does not show in them)
UNCHANGED_ROWS = ("an event flag 4 and its comment", "a blank line between epochs", "power failure (flag 1)")


@pytest.mark.parametrize("case", sorted(READ_ALIKE))
def test_what_georinex_passes_over_or_reads_is_read_alike(synthetic, tmp_path, case):
    path = edited_copy(synthetic, tmp_path, READ_ALIKE[case])
    rows = observation_rows(path)
    assert rows is not None and same_rows(rows, _georinex(path))
    assert same_rows(rows, observation_rows(str(synthetic))) == (case in UNCHANGED_ROWS)  # (the edit shows in the rows)


@pytest.mark.parametrize("case", sorted(LEFT_TO_GEORINEX))
def test_what_the_two_could_read_differently_is_left_to_georinex(synthetic, tmp_path, case):
    from tollcli.errors import TollError

    path = edited_copy(synthetic, tmp_path, LEFT_TO_GEORINEX[case])
    assert observation_rows(path) is None
    logging.disable(logging.ERROR)
    try:
        _georinex(path)  # (georinex reads it, or says what is wrong)
    except TollError:
        pass
    finally:
        logging.disable(logging.NOTSET)


def test_a_file_of_more_epochs_than_georinex_guesses_is_read(tmp_path):
    """georinex's default reading guesses the epochs from the file's size (six satellites an epoch at least) and stops
    with an IndexError past them; this reader reads the file, the rows georinex's careful reading (``fast=False``)
    gives."""
    from tollcli.errors import DataError

    lines = [f"{'2.11':>9}{'':11}{'OBSERVATION DATA':<20}{'G':<20}RINEX VERSION / TYPE\n",
             f"{'     6    C1    L1    D1    S1    C2    L2':<60}# / TYPES OF OBSERV\n", f"{'':60}END OF HEADER\n"]  # fmt: skip
    for k in range(40):
        lines.append(f" 24  5  6  8  0{k:11.7f}  0  2G05G07\n")
        for prn in (5, 7):
            lines.append(f"{21e6 + prn * 1e5 + k:14.3f}  {1.1e8:14.3f}  {-500.0:14.3f}  {45.0:14.3f}  {21e6:14.3f}  \n")
            lines.append(f"{8.6e7:14.3f}  \n")
    path = tmp_path / "two.24o"
    path.write_text("".join(lines))
    with pytest.raises(DataError, match="IndexError"):
        _georinex(path)
    rows = observation_rows(str(path))
    assert rows is not None and len(rows) == 80 and same_rows(rows, _georinex(path, fast=False))


@needs_convbin
def test_damaged_copies_of_a_real_file_are_read_as_georinex_reads_them(walk_rinex2, tmp_path):
    """Twelve copies of the real walk's first 3 s as RINEX 2.11, each with bytes changed, cut or added in its header or
    records: the direct reader gives georinex's rows, or leaves the file to georinex. (Checked when written on 500 such
    copies of its first 60 kB, 199 read alike, 200 of the whole walk, 92, 150 of its RINEX 2.10, 74, and 300 of the
    synthetic file, 71: every other one left to georinex.)"""
    clean = open(walk_rinex2(3.0)[0], "rb").read()
    read_alike = damaged_copies_read_alike(clean, tmp_path, 12, 0.3, b"0123456789 .-+GREC\n56")
    assert read_alike >= 3  # (many damaged copies still read)
