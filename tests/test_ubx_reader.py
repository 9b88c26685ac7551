"""The u-blox raw-measurement reader (``readers/ubx.py``: RXM-RAWX, RXM-SFRBX, NAV-PVT decoded a block of frames at a
time) against pyubx2's decoding of every real UBX log, field by field, and on damaged frames."""

from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest
from conftest import SHARED_DATA, shared

from tollcli.errors import DataError
from tollcli.readers.ubx import RAWX_COLUMNS, SFRBX_COLUMNS, read_ubx, subframe_words
from tollcli.readers.ubx_frames import frame

GPSD = SHARED_DATA / "gpsd"
#: the two long recordings are compared on their first bytes (pyubx2 takes 7 and 16 s over the whole of them)
LONG = (("rtklibexplorer", "gnss_1730.ubx"), ("osnma", "ublox", "current_config.ubx"))
PREFIX_BYTES = 300_000
#: a log whose last bytes are an RTCM 3 frame cut short: pyubx2 (which frames RTCM to step over it) counts it, a UBX
#: reader does not (another protocol on the same port)
CUT_RTCM = "ublox-zed-f9t-rtcm3.log"


def _pyubx2(path) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, int, int]:
    """The RAWX, SFRBX and NAV-PVT tables as pyubx2 decodes them (the reader's layout), its message and error counts."""
    from pyubx2 import UBX_PROTOCOL, UBXReader

    names = {"GPS": 0, "SBAS": 1, "GALILEO": 2, "BEIDOU": 3, "IMES": 4, "QZSS": 5, "GLONASS": 6, "NAVIC": 7}
    as_id = lambda v: int(v) if isinstance(v, (int, np.integer)) else names.get(str(v).upper(), -1)  # noqa: E731
    errors, rawx, sfrbx, pvt, n = [], [], [], [], 0
    with open(path, "rb") as fh:
        reader = UBXReader(fh, protfilter=UBX_PROTOCOL, quitonerror=1, errorhandler=lambda e: errors.append(str(e)))
        while True:
            try:
                raw, msg = reader.read()
            except Exception as exc:  # noqa: BLE001 - a damaged frame, counted
                errors.append(str(exc))
                continue
            if raw is None:
                break
            if msg is None:
                continue
            n += 1
            if msg.identity == "RXM-RAWX":
                for k in range(1, int(msg.numMeas) + 1):
                    rawx.append((msg.rcvTow, msg.week, msg.leapS, *(getattr(msg, f"{c}_{k:02d}") for c in RAWX_COLUMNS[3:]), n))
            elif msg.identity == "RXM-SFRBX":
                words = tuple(int(getattr(msg, f"dwrd_{k:02d}")) for k in range(1, int(msg.numWords) + 1))
                sfrbx.append((as_id(msg.gnssId), int(msg.svId), as_id(msg.sigId), len(words), n, words))
            elif msg.identity == "NAV-PVT":
                pvt.append((msg.year, msg.month, msg.day, msg.hour, msg.min, msg.second, msg.nano, msg.fixType, msg.lat, msg.lon,
                            msg.height / 1000.0, msg.gSpeed / 1000.0, msg.hAcc / 1000.0, msg.sAcc / 1000.0, msg.numSV, n))  # fmt: skip
    rawx = pd.DataFrame(rawx, columns=[*RAWX_COLUMNS, "message"])
    for name in ("gnssId", "sigId"):
        rawx[name] = [as_id(v) for v in rawx[name]]
    width = max((len(row[-1]) for row in sfrbx), default=0)  # the reader's layout: a column per word, zeros past its count
    words = pd.DataFrame([list(row[-1]) + [0] * (width - len(row[-1])) for row in sfrbx], columns=[f"w{i}" for i in range(width)],
                         dtype=np.uint32)  # fmt: skip
    sfrbx = pd.concat([pd.DataFrame([row[:-1] for row in sfrbx], columns=list(SFRBX_COLUMNS)), words], axis=1)
    return (rawx, sfrbx,
            pd.DataFrame(pvt, columns=["year", "month", "day", "hour", "minute", "second", "nano", "fix_type", "lat_deg", "lon_deg",
                                       "height_m", "speed_mps", "h_acc_m", "speed_acc_mps", "n_sv", "message"]), n, len(errors))  # fmt: skip


def _real_ubx_logs(tmp_path) -> list:
    logs = [p for p in sorted(GPSD.glob("*.log")) if b"\xb5\x62" in p.read_bytes()] if GPSD.exists() else []
    for parts in LONG:
        part = tmp_path / parts[-1]
        with open(shared(*parts), "rb") as fh:
            part.write_bytes(fh.read(PREFIX_BYTES))  # (cut mid-frame: a damaged last frame)
        logs.append(part)
    return logs


def test_every_real_ubx_log_reads_as_pyubx2_decodes_it(tmp_path):
    """Every gpsd log with UBX frames, and the first 300 kB of the two long recordings: every RAWX measurement, SFRBX
    subframe and NAV-PVT field pyubx2 decodes, with its dtype and message number, and the same counts."""
    compared = {"rawx": 0, "sfrbx": 0, "pvt": 0}
    logs = _real_ubx_logs(tmp_path)
    assert len(logs) >= 25
    for log in logs:
        theirs = _pyubx2(log)
        if theirs[3] == 0:
            with pytest.raises(DataError, match="no UBX messages"):
                read_ubx(str(log))
            continue
        ours = read_ubx(str(log))
        for k, table in enumerate(("rawx", "sfrbx", "pvt")):
            mine, reference = getattr(ours, table), theirs[k]
            if len(reference):
                pd.testing.assert_frame_equal(mine, reference, obj=f"{log.name} {table}")
            else:
                assert mine.empty and list(mine.columns) == list(reference.columns), (log.name, table)
            compared[table] += len(reference)
        assert ours.n_messages == theirs[3], log.name
        assert ours.n_bad == theirs[4] or (log.name == CUT_RTCM and ours.n_bad == theirs[4] - 1), log.name
    assert compared["rawx"] > 7_000 and compared["sfrbx"] > 4_000 and compared["pvt"] > 1_000, compared


def _rawx(n_meas: int, length_meas: int | None = None) -> bytes:
    head = np.zeros(1, np.dtype([("tow", "<f8"), ("week", "<u2"), ("leap", "i1"), ("n", "u1"), ("rest", "V4")]))
    head["tow"], head["week"], head["leap"], head["n"] = 345600.5, 2300, 18, n_meas
    meas = bytearray()
    for k in range(n_meas if length_meas is None else length_meas):
        one = np.zeros(1, np.dtype([("pr", "<f8"), ("cp", "<f8"), ("do", "<f4"), ("g", "u1"), ("sv", "u1"), ("sig", "u1"),
                                    ("f", "u1"), ("lock", "<u2"), ("cno", "u1"), ("prs", "u1"), ("cps", "u1"), ("dos", "u1"),
                                    ("trk", "u1"), ("r", "u1")]))  # fmt: skip
        one["pr"], one["cp"], one["do"], one["g"], one["sv"], one["cno"] = 2.1e7 + k, 1.1e8, -1234.5, 0, 3 + k, 40
        one["prs"], one["trk"] = 0xF5, 0x03
        meas += one.tobytes()
    return frame(0x02, 0x15, head.tobytes() + bytes(meas))


def test_a_rawx_whose_length_is_not_its_count_is_skipped_counted_or_an_error_in_strict_mode(tmp_path):
    """A RAWX that says 3 measurements and carries 2 is a damaged message: the others are read, it is counted; strict
    names it. A file cut inside a frame counts that frame; the bits of a measurement's flags are read as the interface
    description places them."""
    log = tmp_path / "raw.ubx"
    log.write_bytes(_rawx(2) + _rawx(3, length_meas=2) + _rawx(1) + _rawx(2)[:-10])
    read = read_ubx(str(log))
    assert len(read.rawx) == 3 and read.rawx["message"].tolist() == [1, 1, 3] and read.n_messages == 3 and read.n_bad == 2
    first = read.rawx.iloc[0]
    assert (first["prStd"], first["prValid"], first["cpValid"], first["leapS"], first["doMes"]) == (5, 1, 1, 18, -1234.5)
    with pytest.raises(DataError, match=r"raw\.ubx: UBX message 2: RXM-RAWX of 80 bytes"):
        read_ubx(str(log), strict=True)
    log.write_bytes(_rawx(2) + _rawx(2)[:-10])
    with pytest.raises(DataError, match=r"raw\.ubx: UBX message 2: cut short by the end of the file"):
        read_ubx(str(log), strict=True)


def test_a_damaged_rawx_log_says_how_many_frames_it_skipped(tmp_path):
    """The first 600 kB of the real u-blox walk (its last frame cut short; its orbits complete) through ``integrity``: the
    damaged frame is skipped and counted in the summary; ``--strict`` makes it a one-line error naming the file and the
    message."""
    import json

    from conftest import run_cli

    part = tmp_path / "part.ubx"
    part.write_bytes(shared("rtklibexplorer", "gnss_1730.ubx").read_bytes()[:600_000])
    done = run_cli("integrity", str(part), "-o", str(tmp_path / "i.csv"), "--json", "-q")
    assert done.returncode == 0, done.stderr.decode()
    assert json.loads(done.stdout)["skipped_lines"] == 1
    strict = run_cli("integrity", str(part), "-o", str(tmp_path / "s.csv"), "--strict", "-q")
    err = strict.stderr.decode()
    assert strict.returncode == 1 and err.count("\n") == 1 and f"{part}: UBX message" in err and "cut short" in err, err


@pytest.mark.parametrize("cut", [600_000, 200_000])
def test_every_command_counts_a_damaged_rawx_logs_skipped_frame(tmp_path, cut):
    """The real u-blox walk cut inside a frame, solved from its pseudoranges (600 kB: its orbits complete) or, without
    complete orbits (200 kB), from the receiver's own NAV-PVT instead: ``info``, ``integrity`` (with and without
    ``--checks``) and ``process`` each say the one skipped frame, ``--max-bad 0`` makes it exit 3 after writing, and no
    message names the temporary copy of the log instead of the log. (Before: ``process`` said 0 and ignored
    ``--max-bad`` for every pseudorange log; ``integrity`` said 0 where it fell back to the receiver's solutions or
    ran ``--checks``; ``info`` named the copy.)"""
    import json

    from conftest import REPO, run_cli

    part = tmp_path / "part.ubx"
    part.write_bytes(shared("rtklibexplorer", "gnss_1730.ubx").read_bytes()[:cut])
    geo, tariff = str(REPO / "geoobjects" / "example-geoobjects.geojson"), str(REPO / "geoobjects" / "example-tariff.toml")
    info = run_cli("info", str(part), "--json")
    assert info.returncode == 0 and json.loads(info.stdout)["skipped_lines"] == 1, info.stderr.decode()
    assert "tollcli-log-" not in info.stdout.decode()
    commands = [("integrity", str(part), "-o", str(tmp_path / "i.csv")), ("integrity", str(part), "--checks", "-o", str(tmp_path / "c.csv")),
                ("process", str(part), "--geo", geo, "--tariff", tariff, "-o", str(tmp_path / "inv.json"))]  # fmt: skip
    for args in commands:
        done = run_cli(*args, "--json", "-q")
        assert done.returncode == 0 and json.loads(done.stdout)["skipped_lines"] == 1, (args, done.stderr.decode())
        over = run_cli(*args, "--max-bad", "0", "-q")
        err = over.stderr.decode()
        assert over.returncode == 3 and err.count("\n") == 1 and f"{part}: 1 lines skipped, more than --max-bad 0" in err, (args, err)
        assert "tollcli-log-" not in err and os.path.exists(args[-1])


def test_a_long_recordings_subframes_are_kept_as_numbers_not_python_objects():
    """The Galileo OSNMA recording (28 085 RXM-SFRBX subframes): the first pass keeps each subframe as a row of numbers
    (ids, word count, message, a uint32 column per word), about 100 bytes, where a Python tuple of its words took
    about 400 (`docs/integrity.md`); the words read back as the frames hold them."""
    ubx = read_ubx(str(shared("osnma", "ublox", "current_config.ubx")), measurements=False)
    sf = ubx.sfrbx
    width = sum(c.startswith("w") for c in sf.columns)
    assert len(sf) == 28_085 and width >= 8
    assert all(np.issubdtype(t, np.number) for t in sf.dtypes), sf.dtypes[[not np.issubdtype(t, np.number) for t in sf.dtypes]]
    assert sf.memory_usage(deep=True).sum() / len(sf) <= 8 * len(SFRBX_COLUMNS) + 4 * width + 1
    words, count = subframe_words(sf, width)
    as_tuples = pd.DataFrame({"words": [tuple(int(w) for w in row[:n]) for row, n in zip(words, count)]})
    again, again_count = subframe_words(as_tuples, width)
    assert (again == words).all() and (again_count == count).all() and (words[np.arange(width) >= count[:, None]] == 0).all()
