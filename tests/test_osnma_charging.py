"""Galileo OSNMA as evidence of a charge, on the real u-blox recording (../shared/data/osnma/ublox): each
position and line records whether its navigation data were authenticated, ``--require-authenticated`` makes it
a condition, the position from authenticated satellites alone is compared with the fix, and a forged or
replayed page in the log itself becomes an ``osnma_failure`` finding naming satellite and time — while the
charge, and every finding not about OSNMA, stay as they were.

The recording is of a static receiver (Leuven, 80 min); a geo-object is built around it (a 560 m tolled road,
HAL 50 m) and the RAIM alone is the policy (a stationary receiver fails the speed check by design).
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys

import numpy as np
import pytest

from tollcli.gnss.inav_words import crc24q
from tollcli.gnss.osnma.pages import read_pages, ubx_page_bits
from tollcli.job import pipeline, streaming
from tollcli.job.pipeline import ChargeSettings, charge_log

DATA = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "osnma", "ublox")
LOG = os.path.join(DATA, "current_config.ubx")
pytestmark = pytest.mark.skipif(not os.path.exists(LOG), reason="../shared/data/osnma/ublox not present")
TARIFF = """currency = "EUR"
minor_unit = 2
timezone = "Europe/Brussels"

[road_class.motorway]
car = 0.95
"""
SVID = 31


def _tollcli(*args, check=True):
    return subprocess.run([sys.executable, "-m", "tollcli", *map(str, args)], capture_output=True, text=True, check=check)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """Geo-object and tariff around the receiver, and the recording's key files (for logs written elsewhere)."""
    from tollcli.readers.ubx_nav import iter_ubx_nav_tables

    folder = tmp_path_factory.mktemp("site")
    fixes = np.concatenate([c.epochs[["lat_deg", "lon_deg"]].to_numpy(float) for c in iter_ubx_nav_tables(LOG)])
    lat, lon = np.median(fixes, axis=0)
    roads = {"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {
        "id": "R1", "name": "site road", "road_class": "motorway", "tolled": True},
        "geometry": {"type": "LineString", "coordinates": [[lon - 0.004, lat], [lon + 0.004, lat]]}}]}  # fmt: skip
    (folder / "roads.geojson").write_text(json.dumps(roads))
    _tollcli("geoobjects", "build", folder / "roads.geojson", "--hal", "50", "-o", folder / "geo.geojson")
    (folder / "tariff.toml").write_text(TARIFF)
    return folder


def _process(site, log, out, *extra):
    done = _tollcli("process", log, "--geo", site / "geo.geojson", "--tariff", site / "tariff.toml", "--policy", "raim",
                    "-o", out, "--json", *extra, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def clean(site):
    return _process(site, LOG, site / "clean.json")


# ---- a forger's edit of the log itself: a page's bits changed, its CRC made good, the UBX checksum recomputed ----

def _page_string(words) -> str:
    return "".join(map(str, ubx_page_bits(np.array(words, np.uint64).reshape(1, 8))[0]))


def _words_of(page: str, words) -> tuple[int, ...]:
    """The 8 SFRBX words carrying ``page`` (240 bits), keeping the original words' pad bits."""
    raw = "".join(format(w, "032b") for w in words)
    bits = page[:120] + raw[120:128] + page[120:240] + raw[248:256]
    return tuple(int(bits[32 * k : 32 * k + 32], 2) for k in range(8))


def _with_crc(bits: str) -> str:
    arr = np.frombuffer(bits.encode(), np.uint8) - ord("0")
    data = np.concatenate([np.zeros(4, np.uint8), arr[:114], arr[120:202]])[None, :]
    return bits[:202] + format(int(crc24q(data)[0]), "024b") + bits[226:]


def _rewrite_pages(src: str, dst, new_pages: dict[str, str]) -> int:
    """Copy ``src`` to ``dst`` with every Galileo SFRBX page whose bits are a key of ``new_pages`` replaced by its
    value (payload and UBX checksum rewritten); returns how many frames were rewritten."""
    data = bytearray(open(src, "rb").read())
    at, done = 0, 0
    while (at := data.find(b"\xb5\x62\x02\x13", at)) >= 0:
        length = data[at + 4] | data[at + 5] << 8
        payload = at + 6
        if data[payload] == 2 and data[payload + 1] == SVID and length >= 40:
            words = struct.unpack_from("<8I", data, payload + 8)
            new = new_pages.get(_page_string(words))
            if new is not None:
                struct.pack_into("<8I", data, payload + 8, *_words_of(new, words))
                a = b = 0
                for byte in data[at + 2 : payload + length]:
                    a = (a + byte) & 0xFF
                    b = (b + a) & 0xFF
                data[payload + length], data[payload + length + 1] = a, b
                done += 1
        at += 2
    open(dst, "wb").write(bytes(data))
    return done


def _flipped(bits: str, i: int) -> str:
    return _with_crc(bits[:i] + ("1" if bits[i] == "0" else "0") + bits[i + 1 :])


@pytest.fixture(scope="module")
def pages():
    return read_pages(LOG).table


def _utc_of(pages, row) -> np.datetime64:
    from tollcli.job.osnma_evidence import gst_to_utc

    return gst_to_utc([int(pages.at[row, "wn"]) * 604800 + int(pages.at[row, "tow_s"])]).iloc[0]


def _tampered(site, pages, name, rows_to_bits: dict[int, str]) -> dict:
    log = site / f"{name}.ubx"
    for key in ("OSNMA_MerkleTree.xml", "OSNMA_PublicKey_1.xml", "OSNMA_PublicKey_2.xml"):
        shutil.copy(os.path.join(DATA, key), site / key)  # the keys beside the log, as the operator keeps them
    assert _rewrite_pages(LOG, log, {pages.at[r, "bits"]: b for r, b in rows_to_bits.items()}) == len(rows_to_bits)
    return _process(site, log, site / f"{name}.json")


def _without_osnma(invoice: dict) -> dict:
    """The invoice's charges and non-OSNMA findings: what tampering with navigation pages must not change."""
    lines = [{k: v for k, v in p.items() if k not in ("evidence", "navigation_authentication")} for p in invoice["lines"]]
    found = [f for f in invoice["findings"]["items"] if f["kind"] != "osnma_failure"]
    return {"lines": lines, "total": invoice["total"], "findings": found, "statuses": [p["statuses"] for p in invoice["lines"]]}


def _failures(invoice: dict) -> list[dict]:
    return [f for f in invoice["findings"]["items"] if f["kind"] == "osnma_failure"]


# ---- the clean recording --------------------------------------------------------------------------------------------

def test_each_charge_records_whether_its_positions_rest_on_authenticated_data(clean):
    block = clean["navigation_authentication"]
    assert block["checked"] == "yes" and block["required"] is False and block["failures"] == 0
    assert block["tags_authenticated"] == 4776 and block["kroots_authenticated"] == 60
    assert block["epochs"] == {"authenticated": 3824, "authenticated_subset": 440, "unauthenticated": 489}
    (line,) = clean["lines"]
    assert line["fee"] == "0.95" and line["statuses"] == {"valid": 4753}
    q = line["navigation_authentication"]
    assert q["qualifier"] == "partly" and sum(q["positions"].values()) == len(line["evidence"])
    assert {e["nav_auth"] for e in line["evidence"]} == {"authenticated", "authenticated_subset", "unauthenticated"}
    assert clean["inputs"]["osnma_merkle"].endswith("OSNMA_MerkleTree.xml") and len(clean["inputs"]["osnma_public_keys"]) == 2
    assert not _failures(clean) and "require_authenticated" not in clean["parameters"]


def test_require_authenticated_counts_only_authenticated_positions(site, clean):
    required = _process(site, LOG, site / "required.json", "--require-authenticated")
    (line,) = required["lines"]
    assert line["statuses"] == {"valid": 4264, "unauthenticated": 489}  # 4 264 = epochs with ≥ 4 authenticated used
    assert line["navigation_authentication"]["qualifier"] == "corroborated"
    assert set(line["navigation_authentication"]["positions"]) == {"authenticated", "authenticated_subset"}
    assert required["parameters"]["require_authenticated"] is True and "unauthenticated" in required["status_notes"]
    # the first 2 min 15 s are a cold start (no key yet): nothing before the first authenticated fix counts
    first = min(e["time_utc"] for e in line["evidence"])
    assert first > "2026-03-09T15:03:40" and min(e["time_utc"] for e in clean["lines"][0]["evidence"]) < "2026-03-09T15:01:30"


def test_an_nmea_log_has_nothing_to_authenticate(tmp_path):
    from conftest import REPO, SAMPLES

    geo, tariff = REPO / "geoobjects" / "example-geoobjects.geojson", REPO / "geoobjects" / "example-tariff.toml"
    log = SAMPLES / "straight-drive.nmea"
    plain = json.loads(_tollcli("process", log, "--geo", geo, "--tariff", tariff).stdout)
    assert "navigation_authentication" not in plain and all("nav_auth" not in e for p in plain["lines"] for e in p["evidence"])
    required = json.loads(_tollcli("process", log, "--geo", geo, "--tariff", tariff, "--require-authenticated").stdout)
    assert plain["lines"] and not required["lines"] and required["total"] == "0.00"
    assert all(set(p["statuses"]) - {"valid", "excluded_valid"} for p in required["not_charged"])
    assert required["navigation_authentication"]["checked"].startswith("no")
    assert "unauthenticated" in required["status_notes"]


def test_the_authenticated_satellites_position_stays_near_the_fix(tmp_path):
    """The position from authenticated satellites alone: within 3 m of the receiver's fix on every epoch of the
    recording where it differs from it, far inside the no-fault bound; none disagrees."""
    done = _tollcli("osnma", LOG, "-o", tmp_path / "epochs.csv", "--json")
    s = json.loads(done.stdout)
    assert s["nav_auth_epochs"] == {"authenticated": 3824, "authenticated_subset": 440, "unauthenticated": 489}
    sep = s["auth_sep_m_subset"]
    assert sep["epochs"] == 440 and 0.3 < sep["median"] < 1.5 and sep["max"] < 3.0 and sep["max_over_threshold"] < 0.2
    import pandas as pd

    e = pd.read_csv(tmp_path / "epochs.csv")
    sub = e[e["nav_auth"] == "authenticated_subset"]
    assert (sub["n_used_authenticated"] >= 4).all() and (sub["n_used_authenticated"] < sub["n_galileo_used"]).all()
    from tollcli.geodesy import great_circle_distance_m

    d = great_circle_distance_m(sub["lat_deg"], sub["lon_deg"], sub["auth_lat_deg"], sub["auth_lon_deg"])
    assert np.allclose(d, sub["auth_sep_m"], atol=0.05)  # the reported distance is the one between the positions
    full = e[e["nav_auth"] == "authenticated"]
    assert (full["auth_sep_m"] == 0).all() and (full["n_used_authenticated"] == full["n_galileo_used"]).all()


def test_authentication_adds_fields_and_changes_no_charge(site, clean):
    """Metamorphic: the same log charged without its OSNMA keys gives the same invoice but for the authentication
    fields and the key files (authentication is recorded, not a condition, unless required)."""
    plain = charge_log(LOG, str(site / "geo.geojson"), str(site / "tariff.toml"), ChargeSettings(policy="raim"), osnma_auto=False)[0]
    assert "navigation_authentication" not in plain and not any(k.startswith("osnma") for k in plain["inputs"])

    def strip(invoice):
        d = json.loads(json.dumps(invoice))
        for key in ("navigation_authentication", "content_sha256"):
            d.pop(key, None)
        d["inputs"] = {k: v for k, v in d["inputs"].items() if not k.startswith("osnma") and k != "log"}
        for passage in d["lines"] + d["not_charged"]:
            passage.pop("navigation_authentication", None)
            for item in passage["evidence"]:
                item.pop("nav_auth", None)
        return d

    assert strip(plain) == strip(clean)


def test_the_invoice_verifies_with_its_key_files(site, clean):
    done = _tollcli("verify", site / "clean.json", check=False)
    assert done.returncode == 0, done.stderr


def test_streamed_in_small_chunks_the_invoice_is_the_same(site, clean, monkeypatch):
    settings = ChargeSettings(policy="raim")
    geo, tariff = str(site / "geo.geojson"), str(site / "tariff.toml")
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 1_000_000)
    whole = charge_log(LOG, geo, tariff, settings)[0]
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 97)
    monkeypatch.setattr(pipeline, "BLOCK_BYTES", 4096)
    monkeypatch.setattr(streaming, "ROUND_ROWS", 50)
    streamed = charge_log(LOG, geo, tariff, settings)[0]
    assert streamed["content_sha256"] == whole["content_sha256"]
    assert whole["navigation_authentication"]["epochs"] == clean["navigation_authentication"]["epochs"]


def test_the_check_beside_the_charge_gives_the_invoice_of_the_check_inline(site, clean, monkeypatch):
    """The verification runs in a forked process beside the charge on a machine with two CPUs: the invoice is the one
    of the verification done inline (one CPU), byte for byte; and a broken key file is the same one-line error."""
    import os

    from tollcli.charging.invoice import invoice_json
    from tollcli.errors import TollError

    settings = ChargeSettings(policy="raim")
    geo, tariff = str(site / "geo.geojson"), str(site / "tariff.toml")
    beside = charge_log(LOG, geo, tariff, settings)[0]
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    inline = charge_log(LOG, geo, tariff, settings)[0]
    assert invoice_json(beside) == invoice_json(inline)
    broken = site / "broken-tree.xml"
    broken.write_text("<signalData><MerkleTree>")
    errors = []
    for cpus in ({0}, {0, 1}):
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid, cpus=cpus: cpus)
        with pytest.raises(TollError) as caught:
            charge_log(LOG, geo, tariff, settings, osnma_merkle=str(broken))
        errors.append(str(caught.value))
    assert errors[0] == errors[1] and "broken-tree.xml" in errors[0]


# ---- tampering in the log: caught, named, and nothing else changes ------------------------------------------------

@pytest.fixture(scope="module")
def forged_row(pages):
    """An E31 word type 1 page sent while E31's data were authenticated (a forgery then changes what is)."""
    from tollcli.job.osnma_check import check_osnma

    s = check_osnma(LOG).satellites
    s = s[(s["svid"] == SVID) & (s["constellation"] == "Galileo")]
    authenticated = s.loc[s["nav_authenticated"].to_numpy(bool), "gst_s"].to_numpy(float)
    for row in np.flatnonzero((pages["svid"] == SVID) & (pages["bits"].str[2:8] == "000001"))[60:]:
        t = int(pages.at[row, "wn"]) * 604800 + int(pages.at[row, "tow_s"])
        if np.isin(np.arange(t, t + 60), authenticated).sum() >= 55:
            return int(row)
    raise AssertionError("no such page")


def test_a_forged_ephemeris_word_is_an_osnma_failure_finding_and_the_charge_stays(site, pages, clean, forged_row):
    row = forged_row
    forged = _tampered(site, pages, "forged", {row: _flipped(pages.at[row, "bits"], 2 + 40)})  # a bit of M0
    (f, *more) = _failures(forged)
    assert not more and f["category"] == "spoofing"
    assert f["evidence"]["satellite"] == "E31" and f["evidence"]["failure"] == "tag" and f["evidence"]["failures"] >= 1
    at = _utc_of(pages, row)
    start = np.datetime64(f["start_utc"].rstrip("Z"))
    # known when a tag over the forged data is checked: a slow tag whose cut-off point reaches back to them
    # (here COP 15, 8 min later; the detail names the tag's subframe)
    assert np.timedelta64(0, "s") <= start - np.datetime64(at.tz_convert(None)) <= np.timedelta64(600, "s")
    assert "of E31" in f["evidence"]["detail"] and "does not verify" in f["evidence"]["detail"]
    assert f["lat_deg"] is not None and abs(f["lat_deg"] - 50.8486) < 1e-3
    assert forged["navigation_authentication"]["failures_by_kind"] == {"tag": f["evidence"]["failures"]}
    assert _without_osnma(forged) == _without_osnma(clean)
    # E31's forged data were never authenticated: while E31 sent them its epochs lose "authenticated" (≥ 4 others
    # still give the position: authenticated_subset), until its genuine words come back; nothing else moves
    a, b = forged["navigation_authentication"]["epochs"], clean["navigation_authentication"]["epochs"]
    assert 10 <= b["authenticated"] - a["authenticated"] <= 60
    assert a["authenticated_subset"] - b["authenticated_subset"] == b["authenticated"] - a["authenticated"]
    assert a["unauthenticated"] == b["unauthenticated"]


def test_a_replayed_subframe_is_an_osnma_failure_finding(site, pages, clean):
    mine = pages[pages["svid"] == SVID]
    sf = (mine["wn"] * 604800 + mine["tow_s"]) // 30 * 30
    subframes = [s for s, n in sf.value_counts().sort_index().items() if n == 15]
    old, new = subframes[20], subframes[30]
    src, dst = mine.index[sf == old], mine.index[sf == new]
    replayed = _tampered(site, pages, "replayed", {int(d): pages.at[int(s), "bits"] for s, d in zip(src, dst)})
    found = _failures(replayed)
    assert found and {f["evidence"]["satellite"] for f in found} == {"E31"}
    assert {"key", "tag"} <= {f["evidence"]["failure"] for f in found}
    from tollcli.job.osnma_evidence import gst_to_utc

    replay_utc = gst_to_utc([new]).iloc[0].tz_convert(None)
    assert all(np.datetime64(f["start_utc"].rstrip("Z")) >= np.datetime64(replay_utc) for f in found)
    assert _without_osnma(replayed) == _without_osnma(clean)


def test_findings_reports_the_same_osnma_failures(site, pages, forged_row):
    row = forged_row
    log = site / "forged.ubx"
    if not log.exists():
        _tampered(site, pages, "forged", {row: _flipped(pages.at[row, "bits"], 2 + 40)})
    done = _tollcli("findings", log, "-o", site / "found.json", "--json")
    assert json.loads(done.stdout)["kinds"].get("osnma_failure") == 1
    doc = json.loads((site / "found.json").read_text())
    (f,) = [x for x in doc["findings"] if x["kind"] == "osnma_failure"]
    assert f["evidence"]["satellite"] == "E31" and f["evidence"]["failure"] == "tag"


def test_audit_counts_the_osnma_failure_of_a_forged_log(site, pages, clean, forged_row):
    if not (site / "forged.json").exists():
        _tampered(site, pages, "forged", {forged_row: _flipped(pages.at[forged_row, "bits"], 2 + 40)})
    _tollcli("audit", site / "forged.json", site / "clean.json", "-o", site / "audit.json")
    found = json.loads((site / "audit.json").read_text())["findings"]
    assert [(f["kind"], f["vehicle"], f["evidence"]["satellite"]) for f in found] == [("osnma_failure", "forged.ubx", "E31")]


def _e31_row(pages, tow_mod: int) -> int:
    pick = (pages["svid"] == SVID) & (pages["tow_s"] % 30 == tow_mod) & (np.arange(len(pages)) > 1000)
    return int(np.flatnonzero(pick)[0])


@pytest.mark.parametrize(("what", "tow_mod", "bit", "kind"), [
    ("tag", 1, 146 + 4, "tag"),  # page 0 of the subframe: the first 32 bits of tag 0
    ("key", 23, 146 + 5, "key"),  # page 11: bits 16–47 of the TESLA key
])  # fmt: skip
def test_a_flipped_tag_or_key_bit_is_one_osnma_failure_finding(site, pages, clean, what, tow_mod, bit, kind):
    row = _e31_row(pages, tow_mod)
    tampered = _tampered(site, pages, f"flipped-{what}", {row: _flipped(pages.at[row, "bits"], bit)})
    (f,) = _failures(tampered)
    assert (f["evidence"]["satellite"], f["evidence"]["failure"], f["evidence"]["failures"]) == ("E31", kind, 1)
    start = np.datetime64(f["start_utc"].rstrip("Z")) - np.datetime64(_utc_of(pages, row).tz_convert(None))
    assert np.timedelta64(0, "s") <= start <= np.timedelta64(60, "s")  # named at the subframe it came in
    assert _without_osnma(tampered) == _without_osnma(clean)
    # one tag, or a key the other satellites also sent: no satellite's data lose their authentication
    assert tampered["navigation_authentication"]["epochs"] == clean["navigation_authentication"]["epochs"]
