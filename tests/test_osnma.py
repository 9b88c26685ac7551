"""Galileo OSNMA: the ICD test vectors and a real u-blox recording against OSNMAlib, the open reference
implementation (github.com/Algafix/OSNMA, commit 35957d1), and tampering that must be caught.

The expected counts of the ICD vectors are those OSNMAlib's own test asserts (``tests/icd_test_vectors.py``);
those of the u-blox recording were measured by running OSNMAlib's ``UBX`` input on the same file with its
defaults and the key files beside it (``python -c 'OSNMAReceiver(UBX(...), config).start()'``), counting its
log as its test does.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tollcli.gnss.inav_words import crc24q
from tollcli.gnss.osnma.dsm import read_merkle_tree, read_public_key
from tollcli.gnss.osnma.pages import read_pages
from tollcli.gnss.osnma.receiver import OsnmaSettings, run_osnma

DATA = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "osnma")
ICD1 = os.path.join(DATA, "icd_configuration_1")
ICD2 = os.path.join(DATA, "icd_configuration_2")
UBLOX = os.path.join(DATA, "ublox")
needs = pytest.mark.skipif(not os.path.isdir(DATA), reason="../shared/data/osnma not present")


def _run(pages, folder, key_names):
    tree = read_merkle_tree(os.path.join(folder, "OSNMA_MerkleTree.xml"))
    keys = [read_public_key(os.path.join(folder, k), tree) for k in key_names]
    return run_osnma(pages, OsnmaSettings(tree, keys))


@pytest.fixture(scope="module")
def ublox_pages():
    return read_pages(os.path.join(UBLOX, "current_config.ubx")).table


@pytest.fixture(scope="module")
def ublox_clean(ublox_pages):
    return _run(ublox_pages, UBLOX, ["OSNMA_PublicKey_2.xml"])


@needs
def test_icd_configuration_1_counts_equal_osnmalib():
    r = _run(read_pages(os.path.join(ICD1, "16_AUG_2023_GST_05_00_01_fixed.csv")).table, ICD1, ["OSNMA_PublicKey.xml"])
    c = r.counts
    assert (c["tags_authenticated"], c["data_authenticated"], c["kroots_authenticated"]) == (12532, 6144, 176)
    assert (c["crc_failed"], c["broken_hkroot"], c["failures"]) == (0, 0, 0)


@needs
def test_icd_configuration_2_takes_its_key_from_the_signal_and_counts_equal_osnmalib():
    r = _run(read_pages(os.path.join(ICD2, "27_JUL_2023_GST_00_00_01_fixed.csv")).table, ICD2, [])
    c = r.counts
    assert (c["tags_authenticated"], c["data_authenticated"], c["kroots_authenticated"]) == (11427, 6056, 115)
    assert (c["crc_failed"], c["broken_hkroot"], c["failures"]) == (0, 17, 0)


@needs
@pytest.mark.parametrize("folder, name", [(ICD1, "16_AUG_2023_GST_05_00_01"), (ICD2, "27_JUL_2023_GST_00_00_01")])
def test_icd_vectors_as_published_give_the_pages_of_the_page_per_line_form(folder, name):
    """The published form (each satellite's bit stream from the GST in the file name) and OSNMAlib's page-per-line
    form hold the same pages at the same times, every CRC good."""
    stream = read_pages(os.path.join(folder, name + ".csv")).table
    lines = read_pages(os.path.join(folder, name + "_fixed.csv")).table
    assert stream["crc_ok"].all() and lines["crc_ok"].all()
    cols = ["svid", "wn", "tow_s", "bits"]
    assert stream[cols].equals(lines[cols])


@needs
def test_ublox_recording_equals_osnmalib_on_the_same_file(ublox_clean):
    r = ublox_clean
    c = r.counts
    assert (c["tags_authenticated"], c["data_authenticated"], c["kroots_authenticated"], c["broken_hkroot"]) == (4776, 3128, 60, 27)
    ok = r.tags[r.tags["verified"]]
    assert ok.groupby("adkd").size().to_dict() == {0: 3024, 4: 495, 12: 1257}
    assert r.data.groupby("adkd").size().to_dict() == {0: 1580, 4: 466, 12: 1082}
    wn, tow = divmod(c["first_authenticated_fix_s"] + 2, 604800)
    assert (wn, tow) == (1385, 140641)  # OSNMAlib: "First Authenticated Fix at GST 1385 140641"
    assert c["failures"] == 0 and c["crc_failed"] == 0


@needs
@pytest.mark.parametrize("source, word_types", [("ublox", (0, 5, 6)), ("icd", (0, 5, 6))])
def test_page_time_labels_equal_the_time_the_pages_carry(source, word_types, ublox_pages):
    pages = ublox_pages if source == "ublox" else read_pages(os.path.join(ICD1, "16_AUG_2023_GST_05_00_01_fixed.csv")).table
    word = pages["bits"].str[2:114] + pages["bits"].str[122:138]
    wt = word.str[:6].map(lambda b: int(b, 2))
    tow = {5: word.str[85:105], 6: word.str[105:125], 0: word.str[108:128]}
    checked = 0
    for k in word_types:
        rows = wt == k
        if k == 0:
            rows &= word.str[6:8] == "10"  # word type 0 carries the time only with time field 2
        carried = tow[k][rows].map(lambda b: int(b, 2)).to_numpy()
        assert np.array_equal(carried, pages["tow_s"][rows].to_numpy())
        checked += len(carried)
    assert checked > 1000


@needs
def test_public_key_files_are_checked_against_the_merkle_tree(tmp_path):
    tree = read_merkle_tree(os.path.join(UBLOX, "OSNMA_MerkleTree.xml"))
    assert read_public_key(os.path.join(UBLOX, "OSNMA_PublicKey_2.xml"), tree).verified
    text = open(os.path.join(UBLOX, "OSNMA_PublicKey_2.xml")).read()
    forged = tmp_path / "OSNMA_PublicKey_2.xml"
    forged.write_text(text.replace("02219204b5", "02219204b6"))
    assert not read_public_key(str(forged), tree).verified


# ---- tampering: a bit flipped (and the CRC made good again, as a forger would), or a subframe replayed -----------------

def _with_crc(bits: str) -> str:
    arr = np.frombuffer(bits.encode(), np.uint8) - ord("0")
    data = np.concatenate([np.zeros(4, np.uint8), arr[:114], arr[120:202]])[None, :]
    crc = int(crc24q(data)[0])
    return bits[:202] + format(crc, "024b") + bits[226:]


def _flip(pages, row: int, bit: int):
    out = pages.copy()
    b = out.at[row, "bits"]
    out.at[row, "bits"] = _with_crc(b[:bit] + ("1" if b[bit] == "0" else "0") + b[bit + 1 :])
    return out


def _row(pages, svid: int, tow_mod: int, word_type: int | None = None, after: int = 1000) -> int:
    pick = (pages["svid"] == svid) & (pages["tow_s"] % 30 == tow_mod) & (np.arange(len(pages)) > after)
    if word_type is not None:
        pick &= pages["bits"].str[2:8] == format(word_type, "06b")
    return int(np.flatnonzero(pick)[0])


def _others_unchanged(clean, tampered, svid: int):
    def other(t):
        keep = (t["prn_a"] != svid) & (t["prn_d"] != svid)
        return t[keep][["gst_sf_s", "prn_a", "prn_d", "adkd", "cop", "verified"]].reset_index(drop=True)

    assert other(clean.tags).equals(other(tampered.tags))
    d = lambda t: t[t["prn_d"] != svid][["adkd", "prn_d", "iod", "first_sf_s"]].reset_index(drop=True)  # noqa: E731
    assert d(clean.data).equals(d(tampered.data))


def _failures_name(r, svid: int, kind: str, near_s: int):
    f = r.failures[(r.failures["svid"] == svid) & (r.failures["kind"] == kind)]
    assert len(f), r.failures
    assert (f["gst_s"] >= near_s - 60).all() and (f["gst_s"] <= near_s + 600).all()
    assert all("E" in d or "TESLA" in d for d in f["detail"])


@needs
def test_a_flipped_ephemeris_bit_fails_its_tags_and_nothing_else_changes(ublox_pages, ublox_clean):
    svid = 31
    row = int(np.flatnonzero((ublox_pages["svid"] == svid) & (ublox_pages["bits"].str[2:8] == "000001"))[60])
    t = int(ublox_pages.at[row, "wn"]) * 604800 + int(ublox_pages.at[row, "tow_s"])
    r = _run(_flip(ublox_pages, row, 2 + 40), UBLOX, ["OSNMA_PublicKey_2.xml"])  # a bit of M0 in word type 1
    _failures_name(r, svid, "tag", t)
    assert r.counts["tags_authenticated"] < ublox_clean.counts["tags_authenticated"]
    _others_unchanged(ublox_clean, r, svid)


@needs
def test_a_flipped_tag_bit_fails_that_tag_only(ublox_pages, ublox_clean):
    svid = 31
    row = _row(ublox_pages, svid, tow_mod=1)  # page 0: the first 32 bits of tag 0
    t = int(ublox_pages.at[row, "wn"]) * 604800 + int(ublox_pages.at[row, "tow_s"])
    r = _run(_flip(ublox_pages, row, 146 + 4), UBLOX, ["OSNMA_PublicKey_2.xml"])
    _failures_name(r, svid, "tag", t)
    assert r.counts["tags_authenticated"] == ublox_clean.counts["tags_authenticated"] - 1
    assert len(r.failures) == 1
    _others_unchanged(ublox_clean, r, svid)


@needs
def test_a_flipped_key_bit_breaks_the_chain_for_that_key_only(ublox_pages, ublox_clean):
    svid = 31
    row = _row(ublox_pages, svid, tow_mod=23)  # page 11: the TESLA key's bits 16–47
    t = int(ublox_pages.at[row, "wn"]) * 604800 + int(ublox_pages.at[row, "tow_s"])
    r = _run(_flip(ublox_pages, row, 146 + 5), UBLOX, ["OSNMA_PublicKey_2.xml"])
    _failures_name(r, svid, "key", t)
    assert r.counts["tags_authenticated"] == ublox_clean.counts["tags_authenticated"]
    assert r.counts["data_authenticated"] == ublox_clean.counts["data_authenticated"]
    _others_unchanged(ublox_clean, r, svid)


@needs
def test_a_replayed_subframe_is_not_authenticated(ublox_pages, ublox_clean):
    svid = 31
    p = ublox_pages.copy()
    mine = p[p["svid"] == svid]
    sf = (mine["wn"] * 604800 + mine["tow_s"]) // 30 * 30
    subframes = [s for s, n in sf.value_counts().sort_index().items() if n == 15]
    old, new = subframes[20], subframes[30]
    src, dst = mine.index[sf == old], mine.index[sf == new]
    p.loc[dst, "bits"] = p.loc[src, "bits"].to_numpy()  # the old subframe's pages sent again, now
    r = _run(p, UBLOX, ["OSNMA_PublicKey_2.xml"])
    f = r.failures[r.failures["svid"] == svid]
    assert {"key", "tag"} <= set(f["kind"]) and (f["gst_s"] >= new).all()
    replayed = r.tags[(r.tags["gst_sf_s"] == new) & (r.tags["prn_a"] == svid)]
    assert len(replayed) and not replayed["verified"].any()
    assert r.counts["kroots_authenticated"] >= ublox_clean.counts["kroots_authenticated"] - 1
    _others_unchanged(ublox_clean, r, svid)


@needs
def test_reed_solomon_recovers_the_words_a_satellite_sent(ublox_pages):
    from tollcli.gnss.osnma.navdata import ReedSolomonRecovery

    p = ublox_pages[ublox_pages["svid"] == 31]
    word = (p["bits"].str[2:114] + p["bits"].str[122:138]).tolist()
    kinds = [int(w[:6], 2) for w in word]
    last = {k: w for k, w in zip(kinds, word) if k in (1, 2, 3, 4, 17, 18, 19, 20)}
    # the newest words of one IOD: parity 17–20 alone must give words 1–4 back
    rs = ReedSolomonRecovery()
    for k in (17, 18, 19, 20):
        rs.add_word(k, last[k], 0)
    got = rs.recover()
    iod = last[17][14:16]
    same = [k for k in (1, 2, 3, 4) if last[k][14:16] == iod]
    assert same and all(got[k] == last[k] for k in same if last[k][6:16] == got[1][6:16])


@needs
def test_cli_osnma_writes_epochs_and_a_json_summary(tmp_path):
    out = tmp_path / "epochs.csv"
    cmd = [sys.executable, "-m", "tollcli", "osnma", os.path.join(UBLOX, "current_config.ubx"), "-o", str(out), "--json",
           "--satellites", str(tmp_path / "sats.parquet")]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=True)
    s = json.loads(done.stdout)
    assert s["tags_authenticated"] == 4776 and s["first_authenticated_fix_gst"] == "WN 1385 TOW 140641"
    assert s["public_keys"] == {"1": "not on the Merkle tree: unused", "2": "verified against the Merkle tree"}
    import pandas as pd

    epochs = pd.read_csv(out)
    assert len(epochs) == 4753 and (epochs["n_used_authenticated"] <= epochs["n_galileo_used"]).all()
    assert epochs["n_used_authenticated"].iloc[0] == 0 and epochs["n_used_authenticated"].max() >= 8
    sats = pd.read_parquet(tmp_path / "sats.parquet")
    assert sats.loc[sats["nav_authenticated"], "constellation"].eq("Galileo").all()


def test_cli_osnma_without_a_merkle_tree_is_a_usage_error(tmp_path):
    log = tmp_path / "pages.csv"
    log.write_text("277201,1251,2,021333662A4249DD4A6EBB4CAE1900BD2A5C9E8497BA6AAAAA6A9778C100\n")
    done = subprocess.run([sys.executable, "-m", "tollcli", "osnma", str(log)], capture_output=True, text=True)
    assert done.returncode == 2 and "Merkle" in done.stderr and "Traceback" not in done.stderr
