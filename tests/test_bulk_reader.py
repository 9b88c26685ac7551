"""The bulk NMEA reader against the per-line reference reader: the same tables, statistics and errors.

The reference path (``engine="reference"``) reads one line at a time with the
converters of ``tollcli.readers.nmea.fields`` and was checked against gpsd's own decoding
(test_real_logs). The bulk path must give the same tables on every log: float
columns bit for bit (``pos_disagreement_m`` to 1e-12, numpy's cos and hypot may
differ from math's in the last bit), the same statistics, the same first problem.
"""

from __future__ import annotations

import gzip
import random

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLES, shared
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tollcli.errors import DataError
from tollcli.readers.nmea import ReadStats, bulk_reader, compose, read_nmea


def _read(path, engine, **options):
    stats = ReadStats()
    try:
        tables = read_nmea(path, engine=engine, stats=stats, **options)
    except DataError as exc:
        return None, stats, str(exc)
    return tables, stats, None


def assert_same(path, **options) -> None:
    ref, ref_stats, ref_err = _read(path, "reference", **options)
    bulk, bulk_stats, bulk_err = _read(path, "bulk", **options)
    assert bulk_err == ref_err
    per_line = "per_line_epochs"  # the reference reads every epoch line by line; the bulk reader the rare ones
    assert {k: v for k, v in bulk_stats.as_dict().items() if k != per_line} == {k: v for k, v in ref_stats.as_dict().items() if k != per_line}
    assert bulk_stats.per_line_epochs <= ref_stats.per_line_epochs == ref_stats.epochs
    if ref is None:
        return
    for name in ("epochs", "satellites"):
        a, b = getattr(ref, name), getattr(bulk, name)
        assert list(a.columns) == list(b.columns) and a.shape == b.shape, f"{path}: {name} {a.shape} vs {b.shape}"
        for col in a.columns:
            x, y = a[col], b[col]
            assert x.dtype == y.dtype, f"{path}: {name}.{col} {x.dtype} vs {y.dtype}"
            if x.dtype.kind == "f":
                xv, yv = x.to_numpy(), y.to_numpy()
                if col == "pos_disagreement_m":
                    np.testing.assert_allclose(yv, xv, rtol=1e-12, atol=1e-9, err_msg=f"{path}: {col}")
                else:
                    assert np.array_equal(xv, yv, equal_nan=True), f"{path}: {name}.{col} differs"
            else:
                pd.testing.assert_series_equal(x, y, obj=f"{path}: {name}.{col}")


@pytest.fixture
def readers(monkeypatch) -> list:
    """Every BulkReader made during the test (to see how many epochs it assembled in bulk)."""
    made = []
    original = bulk_reader.BulkReader.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(bulk_reader.BulkReader, "__init__", spy)
    return made


def _gpsd_logs():
    root = shared("gpsd")
    return sorted(p for p in root.iterdir() if p.is_file() and not p.name.endswith(".chk") and "COPYING" not in p.name)


def test_every_gpsd_log_reads_the_same_both_ways(readers):
    fast_logs = []
    logs = _gpsd_logs()
    assert len(logs) >= 170
    for path in logs:
        readers.clear()
        assert_same(path)
        if readers and readers[0].fast_epochs:
            fast_logs.append(path.name)
    # the comparison is not the reference against itself: most logs have epochs assembled in bulk
    assert len(fast_logs) >= 75, len(fast_logs)


@pytest.mark.parametrize("block_bytes", [150, 333, 4096])
def test_block_size_does_not_matter(block_bytes):
    """Epochs cut across blocks are carried whole: tiny blocks give the same tables."""
    for path in (shared("android", "pixel6.nmea"), SAMPLES / "sim" / "urban-fault" / "drive.nmea", SAMPLES / "straight-drive.nmea"):
        assert_same(path, block_bytes=block_bytes)
        ref, _, _ = _read(path, "reference")
        small, _, _ = _read(path, "bulk", block_bytes=block_bytes)
        pd.testing.assert_frame_equal(small.epochs, ref.epochs, check_exact=False, rtol=1e-12)


def test_plain_drive_is_read_entirely_in_bulk(tmp_path, readers):
    log = tmp_path / "drive.nmea"
    log.write_text("\n".join(compose.straight_drive(3000)) + "\n")
    tables = read_nmea(log, block_bytes=50_000)
    assert len(tables.epochs) == 3000
    assert readers[0].fast_epochs == 3000 and readers[0].slow_epochs == 0
    assert_same(log, block_bytes=50_000)


ODD_LOG = [
    "# a comment", "",
    compose.gga(3600.0, 48.1, 11.5),
    compose.rmc(3600.0, 48.1, 11.5, 10.0, 90.0, __import__("datetime").date(2024, 5, 6)),
    "NMEA," + compose.gga(3601.0, 48.1001, 11.5),  # Android prefix
    compose.gga(3602.0, 48.1002, 11.5)[:-2] + "ab",  # lower-case checksum (and wrong)
    compose.gga(3603.0, 48.1003, 11.5)[:-2] + "00",  # bad checksum
    compose.with_checksum("GPGGA,3604,4806.000,N,01130.000,E,1,08,0.9,500.0,M,47.0,M,,"),  # bad time
    compose.with_checksum("GPGGA,010005.00,4899.000,N,01130.000,E,1,08,0.9,500.0,M,47.0,M,,"),  # minutes ≥ 60
    compose.with_checksum("GPGSA,A,3,5.0,07,,,,,,,,,,,1.6,0.9,1.3"),  # a PRN with a point
    compose.with_checksum("GPGSV,1,1,02,05,45,100,40,07,30,200,35,f"),  # lower-case signal id
    compose.with_checksum("GPVTG,90.0,91.0,10.0,18.5"),  # NMEA 1.5 layout
    compose.grs(3606.0, [1.5, -2.0]), compose.gsa([5, 7], 1.6, 0.9, 1.3),
    compose.with_checksum("GPGLL,4806.000,N,01130.000,E,010007.00,A,A"),
    compose.zda(3608.0, __import__("datetime").date(2024, 5, 6)),
    compose.with_checksum("PUBX,00,010008.00,4806.0,N"), "!AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0*26",
    compose.with_checksum("GPGGA,010009.00,4806.000,N,01130.000,E,1,08,0.9,500.0,M,47.0,M,,") + "\r",
    compose.with_checksum("GPGGA,010010.00,-4806.000,N,01130.000,E,1,08,0.9,500.0,M,47.0,M,,"),
    compose.with_checksum("GPGGA,010011.00,4806.000,X,01130.000,E,1,08,0.9,500.0,M,47.0,M,,"),
    compose.with_checksum("GPGGA,010012.00,4806.000,N,01130.000,E,1e0,08,0.9,500.0,M,47.0,M,,"),
    "$GPGGA,010013.00,4806.0",  # truncated
    compose.with_checksum(",NGSA,A,3,05,07,,,,,,,,,,,1.6,0.9,1.3"),  # an empty address
    compose.with_checksum("GNG,A,010014.00,4806.000,N,01130.000,E,1,08,0.9,500.0,M,47.0,M,,"),  # a comma in the address
    "\x00\x01binary junk\xff",
]


def test_odd_lines_are_classified_as_the_reference_does(tmp_path):
    log = tmp_path / "odd.nmea"
    log.write_bytes(("\n".join(ODD_LOG) + "\n").encode("latin-1"))
    assert_same(log)
    stats = _read(log, "bulk")[1]
    assert stats.bad_checksum == 2 and stats.malformed >= 5 and stats.comments == 1 and stats.blank == 1
    ref_error = pytest.raises(DataError, read_nmea, log, engine="reference", strict=True).value
    bulk_error = pytest.raises(DataError, read_nmea, log, engine="bulk", strict=True).value
    assert str(bulk_error) == str(ref_error)
    assert str(bulk_error).startswith(f"{log}:6: bad checksum")  # --strict stops at the first problem line


def test_gzip_and_crlf(tmp_path):
    lines = list(compose.straight_drive(50))
    (tmp_path / "a.nmea.gz").write_bytes(gzip.compress(("\r\n".join(lines) + "\r\n").encode()))
    assert_same(tmp_path / "a.nmea.gz")


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), n_edits=st.integers(1, 30))
def test_damaged_logs_read_the_same_both_ways(tmp_path, seed, n_edits):
    """Random damage (characters dropped, changed, doubled; lines swapped) never makes the two paths differ."""
    rng = random.Random(seed)
    lines = list(compose.straight_drive(40))
    alphabet = "0123456789.,-*$ANEWSVT\r"
    for _ in range(n_edits):
        i = rng.randrange(len(lines))
        line = lines[i]
        j = rng.randrange(len(line))
        action = rng.randrange(4)
        if action == 0:
            line = line[:j] + line[j + 1 :]
        elif action == 1:
            line = line[:j] + rng.choice(alphabet) + line[j + 1 :]
        elif action == 2:
            line = line[:j] + line[j] + line[j:]
        else:
            k = rng.randrange(len(lines))
            lines[i], lines[k] = lines[k], lines[i]
            continue
        if rng.random() < 0.5 and "*" in line:  # keep the checksum right, so the fields are what is damaged
            body = line[1 : line.rfind("*")]
            line = compose.with_checksum(body) if "$" not in body and "*" not in body else line
        lines[i] = line
    log = tmp_path / f"damaged-{seed}.nmea"
    log.write_bytes(("\n".join(lines) + "\n").encode("latin-1"))
    assert_same(log, block_bytes=rng.choice([200, 1000, 1 << 20]))


def test_cli_reader_option_gives_the_same_file(tmp_path):
    from conftest import run_cli

    log = str(SAMPLES / "sim" / "urban-fault" / "drive.nmea")
    outs = []
    for reader in ("bulk", "reference"):
        out = tmp_path / f"{reader}.csv"
        r = run_cli("epochs", log, "-o", str(out), "--reader", reader, "-q")
        assert r.returncode == 0, r.stderr
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    r = run_cli("epochs", log, "--reader", "fast")
    assert r.returncode == 2 and b"--reader fast" in r.stderr


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(reports=st.lists(st.tuples(st.integers(1, 4), st.sampled_from(["", "1", "2", "7", "8"]), st.integers(20, 50)),
                        min_size=1, max_size=10),  # fmt: skip
       gbs_sv=st.sampled_from(["", "08", "23"]))
def test_satellites_on_several_signals_and_gbs_are_read_in_bulk_as_the_reference_does(tmp_path, readers, reports, gbs_sv):
    # NMEA 4.10 receivers (u-blox F9, Unicore, Quectel LC79D) report a satellite once per signal, in any order
    lines = []
    for k in range(3):
        tod = 3600.0 + k
        lines.append(compose.gga(tod, 48.1 + k * 1e-4, 11.5))
        for prn, signal, cn0 in reports:
            body = f"GPGSV,1,1,{len(reports):02d},{prn:02d},{30 + prn},{40 * prn},{cn0}" + (f",{signal}" if signal else "")
            lines.append(compose.with_checksum(body))
        hhmmss = f"0100{k:02d}.00"
        lines.append(compose.with_checksum(f"GNGBS,{hhmmss},1.0,1.3,2.3,{gbs_sv},,12.6,219.6,1,8"))
    log = tmp_path / "signals.nmea"
    log.write_text("\n".join(lines) + "\n")
    readers.clear()
    assert_same(log)
    assert readers[0].slow_epochs == 0 and readers[0].fast_epochs == 3
    tables = read_nmea(log)
    assert tables.stats.per_line_epochs == 0 and tables.stats.epochs == 3


_GGA_PARTS = st.tuples(st.sampled_from(["0", "1", ""]), st.sampled_from(["", "500.0", "505.0"]), st.sampled_from(["", "47.0", "48.0"]),
                       st.sampled_from(["", "8", "10"]))  # fmt: skip


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ggas=st.lists(_GGA_PARTS, min_size=0, max_size=3), gns_at=st.integers(0, 3),
       gns_mode=st.sampled_from(["", "NN", "AN", "NNNNNA", "RRNN"]), gns_alt=st.sampled_from(["", "510.0"]),
       gns_sep=st.sampled_from(["", "46.0"]), gns_n=st.sampled_from(["", "12"]))  # fmt: skip
def test_gns_and_ggas_are_read_in_bulk_as_the_reference_does(tmp_path, readers, ggas, gns_at, gns_mode, gns_alt, gns_sep, gns_n):
    """A GNS among any number of GGAs (a receiver writing one GGA per constellation, as the Telit PLS83):
    altitude, separation, satellites and quality as the reference assembler folds them, in bulk."""
    lines = []
    for k in range(2):
        t = f"0100{k:02d}.00"
        epoch = [compose.with_checksum(f"GPGGA,{t},4806.00{j},N,01130.000,E,{q},{n_used},0.9,{alt},M,{sep},M,,")
                 for j, (q, alt, sep, n_used) in enumerate(ggas)]  # fmt: skip
        gns = compose.with_checksum(f"GNGNS,{t},4806.010,N,01130.000,E,{gns_mode},{gns_n},1.1,{gns_alt},{gns_sep},,")
        epoch.insert(min(gns_at, len(epoch)), gns)
        lines += epoch
    log = tmp_path / "gns.nmea"
    log.write_text("\n".join(lines) + "\n")
    readers.clear()
    assert_same(log)
    assert readers[0].slow_epochs == 0


_REPEATS = st.lists(st.sampled_from(["rmc-a", "rmc-a2", "rmc-v", "rmc-nodate", "vtg", "vtg-n", "vtg-fast", "gll-a", "gll-v",
                                     "gst", "gst2", "gbs", "gbs-sv", "zda", "zda2"]), min_size=1, max_size=12)  # fmt: skip


def _repeated(kind: str, t: str) -> str:
    body = {
        "rmc-a": f"GPRMC,{t},A,4806.000,N,01130.000,E,10.0,90.0,060524,,,A",
        "rmc-a2": f"GARMC,{t},A,4806.020,N,01130.000,E,,45.0,070524,,,D",
        "rmc-v": f"GLRMC,{t},V,4806.040,N,01130.000,E,12.0,91.0,080524,,,N",
        "rmc-nodate": f"GBRMC,{t},A,,,,,11.0,,,,,A",
        "vtg": "GPVTG,92.0,T,,M,9.0,N,16.7,K,A",
        "vtg-n": "GAVTG,93.0,T,,M,9.5,N,17.6,K,N",
        "vtg-fast": "GLVTG,,T,,M,20.0,N,,K,A",
        "gll-a": f"GPGLL,4806.030,N,01130.000,E,{t},A,A",
        "gll-v": f"GAGLL,4806.050,N,01130.000,E,{t},V,N",
        "gst": f"GPGST,{t},1.5,2.0,1.0,30.0,1.8,1.2,3.0",
        "gst2": f"GAGST,{t},,2.5,,,1.9,,",
        "gbs": f"GPGBS,{t},2.3,3.5,4.0,,,,",
        "gbs-sv": f"GAGBS,{t},2.0,,4.1,07,0.01,5.0,1.0",
        "zda": f"GPZDA,{t},06,05,2024,00,00",
        "zda2": f"GNZDA,{t},07,05,2024,00,00",
    }[kind]
    return compose.with_checksum(body)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(first=_REPEATS, second=_REPEATS)
def test_sentences_repeated_in_an_epoch_are_read_in_bulk_as_the_reference_does(tmp_path, readers, first, second):
    """RMC, VTG, GLL, GST, GBS and ZDA written several times in one epoch (once per talker): position, velocity,
    status, mode, date and its disagreement, error ellipse and GBS as the reference folds them, in bulk."""
    lines = [compose.gga(3600.0, 48.1, 11.5)] + [_repeated(k, "010000.00") for k in first]
    lines += [compose.gga(3601.0, 48.1, 11.5)] + [_repeated(k, "010001.00") for k in second]
    log = tmp_path / "repeated.nmea"
    log.write_text("\n".join(lines) + "\n")
    readers.clear()
    assert_same(log)
    assert readers[0].slow_epochs == 0


def _left_to_the_per_line_classifier(address: str, form: str) -> bool:
    """A missing checksum, an empty or too long address, text after the checksum of a sentence of
    another address, and a GGA too short to decode; the rest is classified in bulk."""
    if form == "none":
        return True
    if len(address) == 5 and address[0] != "P":  # plain lines: what follows the checksum is ignored
        return address == "GPGGA" and form in ("ok", "tail")
    return address in ("", "ABCDEFGHI") or form == "tail"


_OTHER_ADDRESSES = ["PSTI", "GYOACC", "PUBX", "GNTXT", "P", "ABCDEFGH", "ABCDEFGHI", "GPGGA", "", "GP,GGA"]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(others=st.lists(st.tuples(st.integers(0, 39), st.sampled_from(_OTHER_ADDRESSES), st.sampled_from(["ok", "bad", "lower", "tail", "none"])),
                       min_size=1, max_size=30))  # fmt: skip
def test_sentences_of_other_addresses_are_classified_in_bulk_as_the_reference_does(tmp_path, readers, monkeypatch, others):
    """Unused sentences with four-, six- or more-character addresses (SkyTraq ``$PSTI``, Unicore ``$GYOACC``)
    with a right, wrong, lower-case (a line written in lower case) or missing checksum or text after it: the same statistics as the reference
    reader, and no epoch read line by line because of them."""
    lines = list(compose.straight_drive(40))
    for at, address, form in sorted(others, reverse=True):
        line = compose.with_checksum(f"{address},1,2.5,X")
        if form == "bad":
            line = line[:-2] + ("00" if line[-2:] != "00" else "11")
        elif form == "lower":
            line = line.lower() if any(c in "ABCDEF" for c in line[-2:]) else line[:-2] + "0a"
        elif form == "tail":
            line += " x"
        elif form == "none":
            line = line[: line.rfind("*")]
        lines.insert(at, line)
    log = tmp_path / "others.nmea"
    log.write_bytes(("\n".join(lines) + "\n").encode("latin-1"))
    readers.clear()
    assert_same(log)
    assert readers[0].slow_epochs == 0
    per_line = []
    original = bulk_reader.classify_line
    with monkeypatch.context() as m:
        m.setattr(bulk_reader, "classify_line", lambda text: per_line.append(text) or original(text))
        _read(log, "bulk")
    left = sum(_left_to_the_per_line_classifier(a, f) for _, a, f in others)
    assert len(per_line) == left, per_line  # only what a whole sentence of another address is not
    assert sum(_read(log, "bulk")[1].unused_types.values()) >= sum(f == "ok" and a not in ("GPGGA", "GP,GGA") for _, a, f in others)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(slots=st.lists(st.sampled_from(["", "03", "07", "12", "23", "65", "201"]), min_size=0, max_size=30),
       sysid=st.sampled_from([None, "", "1", "4", "9"]), lower=st.booleans())  # fmt: skip
def test_gsa_of_any_length_and_lower_case_checksums_are_read_in_bulk(tmp_path, readers, slots, sysid, lower):
    """GSA with more or fewer than twelve satellite slots (the CH-4701 writes 24, i.Trek and TomTom fewer),
    with or without a system id, and sentences whose checksum is written in lower case (Magellan): read in
    bulk, as the reference reads them."""
    lines = []
    for k in range(3):
        body = f"GPGSA,A,3,{','.join(slots)},1.8,1.1,1.5" + (f",{sysid}" if sysid is not None else "")
        gsa = compose.with_checksum(body)
        gga = compose.gga(3600.0 + k, 48.1, 11.5)
        lines += [gga[:-2] + gga[-2:].lower() if lower else gga, gsa]
    log = tmp_path / "gsa.nmea"
    log.write_text("\n".join(lines) + "\n")
    readers.clear()
    assert_same(log)
    ref_stats = _read(log, "reference")[1]
    if ref_stats.malformed == 0:
        assert readers[0].slow_epochs == 0


_JUNK = st.binary(min_size=1, max_size=40).map(lambda b: b.replace(b"\n", b" "))


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(glued=st.lists(st.tuples(st.integers(0, 59), st.one_of(_JUNK, st.sampled_from([b"$", b"  ", b"#", b"NMEA,", b"\xb5b\x01\x07*",
                                                                                          b"!AI", b"\r", b"\xa0\x1c"]))),
                      min_size=1, max_size=20))  # fmt: skip
def test_sentences_after_binary_bytes_are_read_in_bulk_as_the_reference_does(tmp_path, readers, glued):
    """A receiver that writes UBX and NMEA on one port leaves binary bytes before sentences (u-blox ZED-F9T,
    Quectel L76K, ST Teseo's doubled ``$``): the sentence after them is read in bulk, the text before it
    counted as discarded, exactly as the per-line reader does; junk without ``$ ! * #`` or a carriage
    return never sends an epoch to the per-line path."""
    lines = [line.encode("latin-1") for line in compose.straight_drive(6)]
    for at, junk in glued:
        lines[at % len(lines)] = junk + lines[at % len(lines)]
    log = tmp_path / "glued.nmea"
    log.write_bytes(b"\n".join(lines) + b"\n")
    readers.clear()
    assert_same(log, block_bytes=1_000)
    plain_junk = all(not any(c in junk for c in b"$!*#\r") and not junk.strip().startswith(b"NMEA,") for _, junk in glued)
    if plain_junk and _read(log, "reference")[1].malformed == 0:
        assert readers[0].slow_epochs == 0


def _arrays_in_two_stages(path, block_bytes: int, decode_first: bool, strict: bool = False):
    """The bulk reader's epoch arrays and statistics for a log, its blocks fed whole (``feed``) or — as the two
    threads may at worst — every block decoded before the first is taken (``decode_first``); or the error."""
    from tollcli.io.sources import iter_byte_blocks, open_binary

    stats = ReadStats()
    reader = bulk_reader.BulkReader(stats, strict, path.name)
    with open_binary(str(path)) as stream:
        blocks = list(iter_byte_blocks(stream, path.name, block_bytes))
    try:
        if decode_first:
            steps = [reader.decode(b) for b in blocks] + [reader.decode_end()]
            parts = [reader.take(s) for s in steps]
        else:
            parts = [reader.feed(b) for b in blocks] + [reader.finish()]
    except DataError as exc:
        return None, stats.as_dict(), str(exc)
    merged = bulk_reader.merge_arrays([p for p in parts if p is not None]) if any(p is not None for p in parts) else None
    return merged, stats.as_dict(), None


def _same_arrays(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return a.keys() == b.keys() and all(a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f")
                                        for k in a)  # fmt: skip


@pytest.mark.parametrize("block_bytes", [700, 4096])
def test_every_block_decoded_before_any_is_taken_gives_what_one_thread_gives(block_bytes):
    """The reader's two stages (decoding, then counting and assembling) run on two threads a block apart; the
    decoding stage must never read what the assembling one writes (the line count, the epoch numbers). So the
    farthest apart they can be — every block of a log decoded before the first is taken — gives the arrays,
    statistics and first problem of one stage after the other, on every gpsd log, in small blocks."""
    differ = []
    for path in _gpsd_logs():
        serial = _arrays_in_two_stages(path, block_bytes, decode_first=False)
        staged = _arrays_in_two_stages(path, block_bytes, decode_first=True)
        if not (_same_arrays(serial[0], staged[0]) and serial[1:] == staged[1:]):
            differ.append(path.name)
    assert not differ


def test_the_two_stages_apart_in_strict_mode_and_on_the_reference_way(tmp_path, monkeypatch):
    """The routes a log can take beside the bulk one, with the stages a whole log apart: a damaged line in strict
    mode (the same error, naming the same line), time stamps the epoch cut cannot follow (the rest of the log read the
    reference way), and an epoch longer than the carry allows (counted, then the reference way)."""
    lines = (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_text().splitlines()
    damaged = list(lines)
    damaged[len(lines) // 2] = damaged[len(lines) // 2][:-2] + "00"
    log = tmp_path / "damaged.nmea"
    log.write_text("\n".join(damaged) + "\n")
    serial = _arrays_in_two_stages(log, 2048, decode_first=False, strict=True)
    assert serial[2] is not None and f"damaged.nmea:{len(lines) // 2 + 1}:" in serial[2]
    assert _arrays_in_two_stages(log, 2048, decode_first=True, strict=True)[1:] == serial[1:]

    creep = list(lines)  # an epoch whose times creep by 0.4 ms a sentence: the epoch cut gives up, the reference goes on
    i = next(k for k in range(len(lines) // 2, len(lines)) if lines[k].startswith("$GNGGA"))
    for k, extra in ((i, "04"), (next(k for k in range(i, len(lines)) if lines[k].startswith("$GNGST")), "08")):
        body = creep[k][1 : creep[k].rfind("*")].split(",")
        body[1] += extra
        creep[k] = compose.with_checksum(",".join(body))
    odd = tmp_path / "time-creep.nmea"
    odd.write_text("\n".join(creep) + "\n")
    gsv = next(k for k in range(len(lines) // 2, len(lines)) if lines[k].startswith("$GPGSV"))
    long = tmp_path / "long-epoch.nmea"  # an epoch of 7 kB mid-log: longer than the carry allows here
    long.write_text("\n".join(lines[:gsv] + [lines[gsv]] * 100 + lines[gsv:]) + "\n")
    for path, carry in ((odd, bulk_reader.MAX_CARRY_BYTES), (long, 5000)):
        monkeypatch.setattr(bulk_reader, "MAX_CARRY_BYTES", carry)
        made = []
        original = bulk_reader.BulkReader.take

        def spy(self, step):
            made.append(step.route)
            return original(self, step)

        monkeypatch.setattr(bulk_reader.BulkReader, "take", spy)
        serial = _arrays_in_two_stages(path, 2048, decode_first=False)
        staged = _arrays_in_two_stages(path, 2048, decode_first=True)
        monkeypatch.setattr(bulk_reader.BulkReader, "take", original)
        assert serial[2] is None and serial[0]["epoch"].size > 100
        assert _same_arrays(serial[0], staged[0]) and serial[1:] == staged[1:]
        route = bulk_reader.REFERENCE_ROUTE if path is odd else bulk_reader.COUNTED_THEN_REFERENCE
        assert made[0] == bulk_reader.BULK_ROUTE and route in made


def test_decoding_ahead_on_a_thread_gives_the_same_tables_and_errors(tmp_path):
    """``decode_ahead`` (what ``tollcli epochs`` asks for): the next block decoded on a thread of its own gives the
    tables, statistics and strict-mode error of one thread, and leaves no thread behind."""
    import threading

    from tollcli.io.prefetch import THREAD_NAME
    from tollcli.readers.nmea.reader import iter_nmea_tables

    lines = (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_text().splitlines()
    lines[len(lines) * 2 // 3] = lines[len(lines) * 2 // 3][:-2] + "00"
    damaged = tmp_path / "damaged.nmea"
    damaged.write_text("\n".join(lines) + "\n")
    logs = [shared("android", "pixel6.nmea"), SAMPLES / "sim" / "urban-fault" / "drive.nmea", damaged,
            *[p for p in _gpsd_logs() if p.stat().st_size > 30_000]]  # fmt: skip
    assert len(logs) > 10
    for path in logs:
        out = []
        for ahead in (False, True):
            for strict in (False, True):
                stats = ReadStats()
                try:
                    chunks = list(iter_nmea_tables(str(path), stats=stats, strict=strict, block_bytes=1500, chunk_epochs=40,
                                                   decode_ahead=ahead))  # fmt: skip
                    tables = [(c.epochs, c.satellites) for c in chunks]
                    error = None
                except DataError as exc:
                    tables, error = [], str(exc)
                out.append((tables, stats.as_dict(), error))
        for (a, sa, ea), (b, sb, eb) in zip(out[:2], out[2:]):
            assert sa == sb and ea == eb and len(a) == len(b), path.name
            for (e1, s1), (e2, s2) in zip(a, b):
                pd.testing.assert_frame_equal(e1, e2)
                pd.testing.assert_frame_equal(s1, s2)
    assert not [t for t in threading.enumerate() if t.name == THREAD_NAME]
