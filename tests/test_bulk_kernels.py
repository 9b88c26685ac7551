"""The compiled kernels of the bulk reader (``tollcli/readers/nmea/_bulk_kernels.c``) against their numpy versions.

The numpy kernels are the reference (test_bulk_reader checks the whole bulk path
against the per-line reader); the compiled ones must give the same arrays, element
for element, on every gpsd log and on random bytes. The install builds them
(setup.py); where it could not, the reader falls back to numpy, and the first
test says so.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SAMPLES, shared
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tollcli.readers.nmea import bulk_fields, bulk_lines, kernels, read_nmea
from tollcli.readers.nmea.fields import num

FRAME = ("start", "end", "plain", "checksum_ok", "given", "computed", "address", "commas", "first_comma", "n_fields", "n_special")
needs_compiled = pytest.mark.skipif(kernels.compiled is None, reason="compiled kernels not built")


def test_the_install_built_the_compiled_kernels():
    """`pip install .` compiles them (a C compiler and Python's headers are on this machine and in CI)."""
    assert kernels.compiled is not None, "compiled kernels not built (see README: pip install needs a C compiler)"
    assert kernels.compiled.__name__ == "tollcli.readers.nmea._bulk_kernels"


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f":
        return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b))
    return a.dtype == b.dtype and np.array_equal(a, b)


def assert_frame_same(data: bytes) -> bulk_lines.BlockLines:
    fast, ref = bulk_lines.split_block(data), bulk_lines.split_block_numpy(data)
    for name in FRAME:
        assert _same(getattr(fast, name), getattr(ref, name)), (name, data[:200])
    return fast


def assert_fields_same(block: bulk_lines.BlockLines, start: np.ndarray, end: np.ndarray) -> None:
    for integer_only in (False, True):
        fast = bulk_fields.decimal(block, start, end, integer_only)
        ref = bulk_fields.decimal_numpy(block, start, end, integer_only)
        for a, b in zip(fast, ref):
            assert _same(a, b)
    for f, f_ref in ((bulk_fields.time_of_day_s, bulk_fields.time_of_day_s_numpy),
                     (bulk_fields.rmc_date_days, bulk_fields.rmc_date_days_numpy)):  # fmt: skip
        for a, b in zip(f(block, start, end), f_ref(block, start, end)):
            assert _same(a, b), f.__name__


def _logs():
    root = shared("gpsd")
    logs = sorted(p for p in root.iterdir() if p.is_file() and not p.name.endswith(".chk") and "COPYING" not in p.name)
    return [*logs, shared("android", "pixel6.nmea"), SAMPLES / "straight-drive.nmea"]


@needs_compiled
def test_every_real_log_frames_and_reads_the_same_compiled_and_numpy():
    n_fields = 0
    for path in _logs():
        data = path.read_bytes()[:1_500_000]
        cut = data[: data.rfind(b"\n")] if b"\n" in data else data
        for block in (cut, cut[7:], cut[: len(cut) // 3]):
            assert_frame_same(block)
        bl = assert_frame_same(cut)
        plain = np.flatnonzero(bl.plain)
        if not plain.size:
            continue
        lines = np.tile(plain, 24)
        k = np.repeat(np.arange(1, 25), plain.size)
        s, e = bl.field_span(lines, k)
        s_ref, e_ref = bl.field_span_numpy(lines, k)
        assert _same(s, s_ref) and _same(e, e_ref), path.name
        s1, e1 = bl.field_span(plain, 3)  # one field number for every line
        assert _same(s1, s_ref[2 * plain.size : 3 * plain.size]) and _same(e1, e_ref[2 * plain.size : 3 * plain.size])
        assert_fields_same(bl, s, e)
        for integer_only in (False, True):  # span and decimal in one compiled pass: the same as both in turn
            fused = bl.field_decimals(lines, k, integer_only)
            for a, b in zip(fused, bulk_fields.decimal_numpy(bl, s_ref, e_ref, integer_only)):
                assert _same(a, b), path.name
        n_fields += int(np.count_nonzero(e > s))
    assert n_fields > 150_000  # the comparison covered real fields, not empty ones (201 202 on 2026-11-23)


_ALPHABET = b"$!*\r\n,.-+0123456789ABCDEFGPNMEA abce"


@needs_compiled
@settings(max_examples=400, deadline=None)
@example(list(b"\n\n$"), b"NMEA,", [])  # a line too short for its prefix: no specials counted, not -1
@given(st.lists(st.sampled_from(list(_ALPHABET)), max_size=300), st.sampled_from([b"", b"NMEA,", b"$GPGGA,12.5,-3.,00,.5*"]),
       st.lists(st.tuples(st.integers(0, 400), st.integers(0, 20)), max_size=40))  # fmt: skip
def test_random_bytes_frame_and_read_the_same(body, prefix, spans):
    data = prefix + bytes(body)
    bl = assert_frame_same(data)
    start = np.array([min(s, len(data)) for s, _ in spans], np.int64)
    end = np.array([min(s + w, len(data)) for s, w in spans], np.int64).reshape(start.shape)
    assert_fields_same(bl, start, end)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_decimal_fields_match_float_exactly(monkeypatch, compiled):
    if compiled and kernels.compiled is None:
        pytest.skip("compiled kernels not built")
    if not compiled:
        monkeypatch.setattr(kernels, "compiled", None)
    rng = np.random.default_rng(7)
    texts = ["0", "-0", "12", "-12.5", ".5", "5.", "4807.038", "00.000001", "-.5", "123456789012345", "9.99999999999999",
             "1e5", "+5", "-", "", "1.2.3", "12-", "..", "1234567890123456", "12345678.9", "-1234567.8901"]  # fmt: skip
    texts += [f"{x:.{k}f}" for x, k in zip(rng.uniform(-2e4, 2e4, 5000), rng.integers(0, 12, 5000))]
    starts = np.cumsum([0] + [len(t) + 1 for t in texts[:-1]])
    ends = starts + np.array([len(t) for t in texts])
    block = bulk_lines.split_block(",".join(texts).encode())
    value, ok, empty, dotted = bulk_fields.decimal(block, starts, ends)
    for text, v, good, e, d in zip(texts, value, ok, empty, dotted):
        if e:
            assert good and np.isnan(v)
            continue
        if good:  # read in bulk: exactly float(), and the point seen
            assert v == num(text) and np.signbit(v) == np.signbit(num(text)), text
            assert d == ("." in text)
        else:  # left to the per-line converters: only forms the bulk path does not read
            assert any(c in text for c in "e+") or text.count(".") > 1 or text in ("-", "12-", "..") or len(text.lstrip("-")) > 15, text


def test_reader_without_the_compiled_kernels_gives_the_same_tables(monkeypatch):
    """What an install without a C compiler reads (TOLLCLI_KERNELS=numpy): the same tables."""
    paths = [SAMPLES / "straight-drive.nmea", SAMPLES / "sim" / "urban-fault" / "drive.nmea", shared("android", "pixel6.nmea")]
    fast = [read_nmea(p) for p in paths]
    monkeypatch.setattr(kernels, "compiled", None)
    for p, a in zip(paths, fast):
        b = read_nmea(p)
        for name in ("epochs", "satellites"):
            x, y = getattr(a, name), getattr(b, name)
            assert list(x.columns) == list(y.columns) and x.shape == y.shape, p
            for col in x.columns:
                xv, yv = x[col].to_numpy(), y[col].to_numpy()
                if xv.dtype.kind == "f":
                    assert np.array_equal(xv, yv, equal_nan=True), (p, col)
                else:
                    assert (x[col].astype(str) == y[col].astype(str)).all(), (p, col)


def test_kernels_reject_mismatched_buffers():
    """A wrong size from a caller is an error, not a write past an array's end."""
    if kernels.compiled is None:
        pytest.skip("compiled kernels not built")
    buf = np.frombuffer(b"$GPGGA,1,2*00\n$GPGGA,3*00", np.uint8)
    def frame(lines: int, commas: int):
        i64 = [np.empty(lines, np.int64) for _ in range(8)]
        kernels.compiled.frame(buf, i64[0], i64[1], np.empty(lines, bool), i64[2], i64[3], i64[4],
                               np.empty(commas, np.int64), i64[5], i64[6], i64[7])  # fmt: skip

    frame(2, 3 + 2)  # right: two lines, three commas and the two sentinels
    with pytest.raises(ValueError):
        frame(2, 1)  # no room for the sentinels
    with pytest.raises(ValueError):
        frame(1, 3 + 2)  # one line too few for the buffer
    with pytest.raises(ValueError):
        frame(2, 2 + 2)  # a comma too few
    with pytest.raises(ValueError):
        kernels.compiled.decimal(buf, np.zeros(3, np.int64), np.zeros(3, np.int64), False, np.empty(2), *[np.empty(3, bool)] * 3)
    bl = bulk_lines.split_block(buf.tobytes())
    with pytest.raises(IndexError):
        bl.field_span(np.array([5]), 1)
    with pytest.raises(IndexError):
        bl.field_decimals(np.array([5]), 1)
    with pytest.raises(ValueError):
        kernels.compiled.field_decimal(bl.buf, bl.first_comma, bl.end, bl.commas, np.array([0, 1]), np.array([1, 1]), False,
                                       np.empty(1), *[np.empty(2, bool)] * 3)  # fmt: skip


@needs_compiled
def test_gsa_slots_compiled_and_numpy_are_the_same(monkeypatch):
    """The GSA satellite slots read in one compiled pass equal the numpy reading, on every real log's GSA lines
    (any slot count, system ids, bad numbers) and on a GSA of 24 and of 40 slots."""
    extra = b"\n".join([b"$GPGSA,A,3," + b",".join(b"%02d" % i for i in range(1, 25)) + b",1.0,2.0,3.0*00",
                         b"$GPGSA,A,3," + b",".join(b"%02d" % i for i in range(1, 41)) + b",1.0,2.0,3.0*00",
                         b"$GPGSA,A,3,01,-2,3.5,1024,,x,07,,,,,,1.0,2.0,3.0,4*00", b""])  # fmt: skip
    n_gsa, _ = _decoded_alike(monkeypatch, "GSA", extra)
    assert n_gsa > 2_000


def _decoded_alike(monkeypatch, sentence: str, extra: bytes) -> tuple[int, int]:
    """Every real log's ``sentence`` lines (and ``extra``) decoded by the compiled kernels and by numpy, held equal;
    (lines compared, lines the bulk path refused)."""
    from tollcli.readers.nmea import bulk_sentences
    from tollcli.readers.nmea.bulk_lines import pack_address, type_code

    decode = getattr(bulk_sentences, sentence.lower())
    n_lines = refused = 0
    for path in [*_logs(), None]:
        data = extra if path is None else path.read_bytes()[:1_500_000]
        cut = data[: data.rfind(b"\n")] if b"\n" in data else data
        bl = bulk_lines.split_block(cut)
        idx = np.flatnonzero(bl.plain & (type_code(bl.address) == pack_address("XX" + sentence) >> 16))
        if not idx.size:
            continue
        fast = decode(bl, idx)
        with monkeypatch.context() as m:
            m.setattr(kernels, "compiled", None)
            ref = decode(bl, idx)
        assert fast.keys() == ref.keys()
        for key in fast:
            assert _same(fast[key], ref[key]), (path, key)
        n_lines += idx.size
        refused += int((~fast["ok"]).sum())
    return n_lines, refused


@needs_compiled
def test_gsv_groups_compiled_and_numpy_are_the_same(monkeypatch):
    """The GSV satellite groups read in one compiled pass equal the numpy reading, on every real log's GSV lines
    (signal ids, empty groups, NMEA 4.10 and older) and on groups the bulk path must refuse: a dotted or too large
    number, an elevation beyond ±90°, an azimuth beyond 360°, an exponent; numbers of one to three digits beside
    longer ones, signs, spaces, letters and lone dots (the kernel's short-number path and its fallback)."""
    extra = b"\n".join([b"$GPGSV,3,1,11,01,45,120,40,02,-91,10,,03,5.0,,30,04,,361,*00",
                        b"$GPGSV,3,1,11,1.5,45,120,40,1024,1,1,1,x,1,1,1,07,1,1,1e3*00",
                        b"$GLGSV,1,1,02,65,10,20,30,70,,,*00", b"$GAGSV,1,1,01,05,10,20,30,7*00",
                        b"$GPGSV,1,1,04,0009,+5,999,9a,10, 5,20 ,-5,11,00,000,00,12,9.,.5,1/*00", b""])  # fmt: skip
    n_gsv, refused = _decoded_alike(monkeypatch, "GSV", extra)
    assert n_gsv > 5_000 and refused >= 2


@needs_compiled
@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(0, 2), st.integers(1, 4), st.integers(-1, 3)), max_size=60))
def test_gsv_report_kept_per_satellite_compiled_and_numpy_are_the_same(rows):
    """The GSV report kept for each satellite of an epoch (the lowest signal id after the last report without one, the
    last of equals) picked in one compiled pass equals the numpy picking, on any order of reports within epochs."""
    from tollcli.readers.nmea import bulk_epochs

    rows = sorted(rows, key=lambda r: r[0])  # epochs in line order; within them, the reports as drawn
    e, const, svid, signal = (np.array([r[k] for r in rows], np.int64) for k in range(4))
    code = const * 1024 + svid
    compiled = bulk_epochs._gsv_reports(e, code, signal)
    assert np.array_equal(compiled, bulk_epochs._gsv_reports_numpy(e, code, signal))
    if e.size:  # each satellite of each epoch keeps exactly one report
        assert np.array_equal(np.unique(e[compiled] * 4096 + code[compiled]), np.unique(e * 4096 + code))
        assert compiled.size == np.unique(e * 4096 + code).size


@needs_compiled
def test_gsv_reports_out_of_epoch_order_fall_back_to_numpy():
    """Rows whose epochs go back (never from the reader, which numbers epochs in line order) are left to numpy."""
    from tollcli.readers.nmea import bulk_epochs

    chosen = np.empty(3, np.uint8)
    e, code, signal = np.array([1, 0, 0]), np.array([1, 1, 2]), np.array([0, 1, 0])
    assert kernels.compiled.gsv_reports(e, code, signal, chosen) is False
    assert np.array_equal(bulk_epochs._gsv_reports(e, code, signal), bulk_epochs._gsv_reports_numpy(e, code, signal))
