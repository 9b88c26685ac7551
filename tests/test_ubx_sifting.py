"""A u-blox log's first pass keeps only the navigation subframes that can still change its orbits
(``read_ubx(subframes_kept=sfrbx_kept)``, :func:`tollcli.gnss.ubx_measurements.sfrbx_kept`): the same ephemerides, the
memory of the orbits and not of the log.

Known answers: every real log in ``../shared/data`` with RXM-SFRBX (gpsd's four, the triple-band walk, the OSNMA
recording: GPS LNAV, Galileo I/NAV, BeiDou D1 and GLONASS strings), sifted after every 2 kB block, decodes to the
ephemerides of the whole log, to the bit. Metamorphic: the OSNMA recording twice over (the same pages again) keeps
the same subframes and gives the same ephemerides.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from conftest import SHARED_DATA, shared

from tollcli.gnss.ubx_measurements import receive_times_gps_s, sfrbx_ephemerides, sfrbx_kept, times_kept
from tollcli.readers import ubx

#: the real logs with navigation subframes, and the systems each decodes
LOGS = {("gpsd", "ublox-glo.log"): "R", ("gpsd", "ublox-ned-m8t-sbfrx3.log"): "G", ("gpsd", "ublox-x20p.log"): "CEG",
        ("gpsd", "ublox-zed-f9p-sfrbx.log"): "CER", ("rtklibexplorer", "gnss_1730.ubx"): "CEG",
        ("osnma", "ublox", "current_config.ubx"): "E"}  # fmt: skip
OSNMA = ("osnma", "ublox", "current_config.ubx")


def _sifted(path: str, monkeypatch, **kw) -> ubx.UbxRead:
    """``path`` read with its subframes sifted after every block (of 2 kB: many sifts, each cutting the log anew)."""
    monkeypatch.setattr(ubx, "SIFT_SUBFRAMES", 1)
    return ubx.read_ubx(path, block_bytes=2048, subframes_kept=sfrbx_kept, **kw)


def _times_sifted(path: str, monkeypatch, **kw) -> ubx.UbxRead:
    """``path``'s first pass with its subframes and its RAWX heads and NAV-PVT rows sifted after every block."""
    monkeypatch.setattr(ubx, "SIFT_TIMES", 1)
    return _sifted(path, monkeypatch, measurements=False, times_kept=times_kept, **kw)


@pytest.mark.parametrize("parts", list(LOGS), ids=lambda p: p[-1])
def test_every_real_first_pass_with_its_times_sifted_gives_the_same_orbits_and_times(monkeypatch, parts):
    """The first pass as a long log's (no measurements kept), its RAWX heads and NAV-PVT rows sifted too: the same
    ephemerides to the bit, the same check that measurements are there, the same receive time for each of the
    GLONASS strings it kept, and far fewer rows kept where the log has many."""
    path = str(shared(*parts))
    whole = ubx.read_ubx(path, measurements=False)
    sifted = _times_sifted(path, monkeypatch)
    pd.testing.assert_frame_equal(sfrbx_ephemerides(sifted), sfrbx_ephemerides(whole))
    measured = lambda r: bool((r.rawx_heads["numMeas"].to_numpy() > 0).any())  # noqa: E731
    assert measured(sifted) == measured(whole)
    glonass = sifted.sfrbx["message"].to_numpy(np.int64)[sifted.sfrbx["gnssId"].to_numpy() == 6]  # (the strings kept)
    np.testing.assert_array_equal(receive_times_gps_s(sifted, glonass), receive_times_gps_s(whole, glonass))
    assert sifted.n_bad == whole.n_bad and len(sifted.pvt) <= len(whole.pvt) and len(sifted.rawx_heads) <= len(whole.rawx_heads)
    if len(whole.rawx_heads) + len(whole.pvt) > 1000:  # (the walk, the OSNMA recording)
        assert len(sifted.rawx_heads) + len(sifted.pvt) < 0.05 * (len(whole.rawx_heads) + len(whole.pvt))


def test_a_recording_eight_times_over_keeps_as_many_times_as_once(tmp_path, monkeypatch):
    """Metamorphic: the OSNMA recording written 8 times over (the same messages again, 10 h 40 min): its first pass
    keeps no more RAWX heads and NAV-PVT rows than the recording once, and the same ephemerides."""
    data = shared(*OSNMA).read_bytes()
    eight = tmp_path / "eight.ubx"
    eight.write_bytes(data * 8)
    once = ubx.read_ubx(str(shared(*OSNMA)), measurements=False, subframes_kept=sfrbx_kept, times_kept=times_kept)
    many = ubx.read_ubx(str(eight), measurements=False, subframes_kept=sfrbx_kept, times_kept=times_kept)
    whole_once = ubx.read_ubx(str(shared(*OSNMA)), measurements=False)
    assert len(many.rawx_heads) + len(many.pvt) <= len(once.rawx_heads) + len(once.pvt) + ubx.SIFT_TIMES
    assert (len(whole_once.rawx_heads) + len(whole_once.pvt)) * 8 > 4 * ubx.SIFT_TIMES  # (the sifting had rows to cut)
    pd.testing.assert_frame_equal(sfrbx_ephemerides(many), sfrbx_ephemerides(once))


@pytest.mark.parametrize("parts", list(LOGS), ids=lambda p: p[-1])
def test_every_real_log_sifted_block_by_block_gives_the_same_ephemerides(monkeypatch, parts):
    path = str(shared(*parts))
    whole = ubx.read_ubx(path)
    expected = sfrbx_ephemerides(whole)
    sifted = _sifted(path, monkeypatch)
    got = sfrbx_ephemerides(sifted)
    pd.testing.assert_frame_equal(got, expected)
    assert set(expected["sv"].str[0]) == set(LOGS[parts])  # each decoder had its work
    assert set(sifted.sfrbx["message"]) <= set(whole.sfrbx["message"])  # rows kept, none made
    assert len(sifted.sfrbx) < len(whole.sfrbx)
    for column in ("rawx", "pvt", "rawx_heads"):  # the rest of the first pass is as read
        pd.testing.assert_frame_equal(getattr(sifted, column), getattr(whole, column))


def test_the_first_pass_of_the_osnma_recording_keeps_its_orbits_subframes_not_its_length(monkeypatch):
    """28 085 Galileo pages, 67 ephemerides: the sifted first pass holds a few pages per ephemeris (the last word types
    1–4 of each, the word types 5 around them), and as the default sifts them, under 3 % of the pages."""
    path = str(shared(*OSNMA))
    whole = ubx.read_ubx(path, measurements=False)
    n_eph = len(sfrbx_ephemerides(whole))
    fine = _sifted(path, monkeypatch, measurements=False)
    assert len(whole.sfrbx) == 28085 and n_eph == 67
    kept = int(sfrbx_kept(fine.sfrbx).sum())  # (the table holds those and the pages read since its last sifting)
    assert kept <= 7 * n_eph and len(fine.sfrbx) <= 2 * kept + 1
    monkeypatch.undo()
    default = ubx.read_ubx(path, measurements=False, subframes_kept=sfrbx_kept)
    assert len(default.sfrbx) < 0.03 * len(whole.sfrbx)


def test_a_recording_twice_over_keeps_as_many_subframes_and_the_same_ephemerides(tmp_path, monkeypatch):
    """Metamorphic: the same pages again after the recording (each replaces its own copy: the last of each issue is
    kept) leaves the subframes kept as many as for the recording once, and the ephemerides unchanged."""
    data = shared(*OSNMA).read_bytes()
    twice = tmp_path / "twice.ubx"
    twice.write_bytes(data + data)
    once = _sifted(str(shared(*OSNMA)), monkeypatch, measurements=False)
    doubled = _sifted(str(twice), monkeypatch, measurements=False)
    assert sfrbx_kept(doubled.sfrbx).sum() == sfrbx_kept(once.sfrbx).sum() < 7 * 67
    assert doubled.sfrbx["message"].min() > once.sfrbx["message"].max()  # the second copy's pages, not the first's
    pd.testing.assert_frame_equal(sfrbx_ephemerides(doubled), sfrbx_ephemerides(once))


def test_a_beidou_triple_cut_by_the_sifting_needs_its_recent_subframes(monkeypatch):
    """The sifting's reach, on the walk: a subframe 1 or 2 whose triple is not complete when it is sifted is kept as
    recent (:data:`tollcli.gnss.beidou_d1.LATE_S`); with nothing kept as recent, sifting after every 2 kB block loses
    all 8 BeiDou ephemerides (the test above then fails)."""
    from tollcli.gnss import beidou_d1

    path = str(shared("rtklibexplorer", "gnss_1730.ubx"))
    expected = sfrbx_ephemerides(ubx.read_ubx(path, measurements=False))
    monkeypatch.setattr(beidou_d1, "LATE_S", 0.0)
    got = sfrbx_ephemerides(_sifted(path, monkeypatch, measurements=False))
    assert (expected["sv"].str[0] == "C").sum() == 8 and not (got["sv"].str[0] == "C").any()
    others = expected[expected["sv"].str[0] != "C"].reset_index(drop=True)
    pd.testing.assert_frame_equal(got, others[got.columns], check_dtype=False)  # (without BeiDou: no TGD1, TGD2; health int)


@pytest.fixture(autouse=True)
def _data():
    if not SHARED_DATA.exists():
        pytest.skip("../shared/data not found")
