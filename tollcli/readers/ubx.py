"""u-blox UBX binary logs → raw-measurement, navigation-data and PVT tables, decoded a block of frames at a time.

* ``RXM-RAWX`` (0x02 0x15): one row per measurement — receiver time of week and week (GPS time of the receiver's
  clock), pseudorange (m), carrier phase (cycles), Doppler (Hz), C/N0, standard deviations
  (0.01·2ⁿ m, 0.004 cycles, 0.002·2ⁿ Hz as the message codes them), tracking flags;
* ``RXM-SFRBX`` (0x02 0x13): one row per navigation-data subframe (satellite and its 32-bit words), decoded
  into ephemerides in :mod:`tollcli.gnss.lnav_subframes`;
* ``NAV-PVT`` (0x01 0x07): the receiver's own solution (time, position, ground speed, accuracies), for comparison.

The frames come from :func:`~tollcli.readers.ubx_frames.iter_frame_blocks` (found by their lengths, checksums checked
for a block at once) and each message's fields are read for all its frames of a block at once, as numpy records at
the offsets of the u-blox interface description (``tests/test_ubx_reader.py`` checks every real log against pyubx2's
decoding, field by field). Frames that fail their checksum, and messages whose length is not what their counts say,
are skipped and counted (NMEA and RTCM between the UBX frames are not errors: they are another protocol on the same
port); ``strict`` makes the first an error naming the message.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError
from tollcli.readers.nmea.line_reader import ReadStats
from tollcli.readers.ubx_frames import iter_frame_blocks
from tollcli.times import plausible_date

UBX_SYNC = b"\xb5\x62"
#: UBX gnssId → constellation name
GNSS_ID = {0: "GPS", 1: "SBAS", 2: "Galileo", 3: "BeiDou", 5: "QZSS", 6: "GLONASS", 7: "NavIC"}
RAWX_COLUMNS = ("rcvTow", "week", "leapS", "prMes", "cpMes", "doMes", "gnssId", "svId", "sigId", "freqId", "locktime",
                "cno", "prStd", "cpStd", "doStd", "prValid", "cpValid")  # fmt: skip
RXM_RAWX, RXM_SFRBX, NAV_PVT = (0x02, 0x15), (0x02, 0x13), (0x01, 0x07)

#: RXM-RAWX: its 16-byte head, then 32 bytes a measurement (numMeas at byte 11)
_RAWX_HEAD = np.dtype({"names": ["rcvTow", "week", "leapS", "numMeas"], "formats": ["<f8", "<u2", "i1", "u1"],
                       "offsets": [0, 8, 10, 11], "itemsize": 16})  # fmt: skip
_RAWX_MEAS = np.dtype({"names": ["prMes", "cpMes", "doMes", "gnssId", "svId", "sigId", "freqId", "locktime", "cno", "prStdev",
                                 "cpStdev", "doStdev", "trkStat"],
                       "formats": ["<f8", "<f8", "<f4", "u1", "u1", "u1", "u1", "<u2", "u1", "u1", "u1", "u1", "u1"],
                       "offsets": [0, 8, 16, 20, 21, 22, 23, 24, 26, 27, 28, 29, 30], "itemsize": 32})  # fmt: skip
#: NAV-PVT: the fields read (92 bytes since protocol 14; the 84 of earlier versions hold them all)
_PVT = np.dtype({"names": ["year", "month", "day", "hour", "minute", "second", "nano", "fix_type", "n_sv", "lon", "lat", "height",
                           "h_acc", "g_speed", "s_acc"],
                 "formats": ["<u2", "u1", "u1", "u1", "u1", "u1", "<i4", "u1", "u1", "<i4", "<i4", "<i4", "<u4", "<i4", "<u4"],
                 "offsets": [4, 6, 7, 8, 9, 10, 16, 20, 23, 24, 28, 32, 40, 60, 68], "itemsize": 84})  # fmt: skip
PVT_MIN_LENGTH = 84
HEAD_COLUMNS = ("rcvTow", "week", "leapS", "numMeas", "message")
#: an RXM-SFRBX row's columns before its words (``w0`` … ``w{n-1}``, n the log's most words in one subframe): each
#: word a column of 4 bytes, not a Python tuple of integers (≈ 400 bytes a subframe)
SFRBX_COLUMNS = ("gnssId", "svId", "sigId", "n_words", "message")
PVT_COLUMNS = ("year", "month", "day", "hour", "minute", "second", "nano", "fix_type", "lat_deg", "lon_deg", "height_m",
               "speed_mps", "h_acc_m", "speed_acc_mps", "n_sv", "message")  # fmt: skip


@dataclass
class UbxRead:
    rawx: pd.DataFrame  # one row per RXM-RAWX measurement (RAWX_COLUMNS + ``message``)
    sfrbx: pd.DataFrame  # one row per RXM-SFRBX: SFRBX_COLUMNS, then its words w0, w1, … (uint32; 0 past n_words)
    pvt: pd.DataFrame  # one row per NAV-PVT
    n_messages: int  # good UBX frames
    n_bad: int  # UBX frames that failed their checksum, or whose message's length is not what its counts say
    rawx_heads: pd.DataFrame | None = None  # one row per RXM-RAWX: rcvTow, week, leapS, numMeas, message


def subframe_words(frame: pd.DataFrame, width: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``width`` words of each subframe of ``frame`` as a (rows, ``width``) uint32 array (zeros past a
    subframe's words) and each subframe's word count: from the reader's ``w0`` … columns and ``n_words``
    (:data:`SFRBX_COLUMNS`), or from a ``words`` column of sequences (a table made elsewhere: a test's, an encoder's)."""
    out = np.zeros((len(frame), width), np.uint32)
    if "words" in frame:
        sequences = [np.asarray(w, np.uint32) for w in frame["words"]]
        for i, w in enumerate(sequences):
            out[i, : min(w.size, width)] = w[:width]
        return out, np.array([w.size for w in sequences], np.int64)
    columns = [f"w{i}" for i in range(width) if f"w{i}" in frame]  # (the log's subframes may all be shorter)
    out[:, : len(columns)] = frame[columns].to_numpy(np.uint32)
    return out, frame["n_words"].to_numpy(np.int64)


def last_of_each(ok: np.ndarray, *keys: np.ndarray) -> np.ndarray:
    """(n,) whether each row is, among the rows ``ok``, the last of its key (the tuple of ``keys``' values, each (n,)
    integers): what ``drop_duplicates(keys, keep="last")`` keeps of the rows ``ok``."""
    out = np.zeros(ok.size, bool)
    rows = np.flatnonzero(ok)
    if rows.size:
        table = pd.DataFrame({i: np.asarray(k, np.int64)[rows] for i, k in enumerate(keys)})
        out[rows[~table.duplicated(keep="last").to_numpy()]] = True
    return out


def is_ubx(head: bytes) -> bool:
    """Whether the first bytes of a file hold a UBX frame (sync chars followed by a known class)."""
    at = head.find(UBX_SYNC)
    return at >= 0 and at + 2 < len(head) and head[at + 2] in (0x01, 0x02, 0x05, 0x06, 0x0A, 0x0D, 0x10, 0x13, 0x21, 0x27, 0x28)


def _records(data: np.ndarray, offsets: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """The ``dtype`` records at byte ``offsets`` of ``data`` (uint8), gathered at once."""
    if not offsets.size:
        return np.zeros(0, dtype)
    return data[offsets[:, None] + np.arange(dtype.itemsize)].view(dtype).ravel()


#: subframes held before a first pass's ``subframes_kept`` sifts them (then: once they have doubled since)
SIFT_SUBFRAMES = 1024
#: RXM-RAWX heads and NAV-PVT rows held before a first pass's ``times_kept`` sifts them (then: once doubled since)
SIFT_TIMES = 4096


class _Tables:
    """The columns of the messages read so far, a block's arrays at a time. ``subframes_kept``: a function of a
    subframe table (:func:`read_ubx`'s ``sfrbx`` layout, the rows in log order) giving the rows to keep; where given,
    the subframes are sifted through it as they pile up (:data:`SIFT_SUBFRAMES`)."""

    def __init__(self, measurements: bool = True, subframes_kept=None, times_kept=None) -> None:
        self.measurements = measurements
        self.rawx: list[dict] = []
        self.heads: list[dict] = []
        self.sfrbx: list[tuple] = []
        self.pvt: list[dict] = []
        self.subframes_kept = subframes_kept
        self._held = 0  # subframe rows held
        self._sift_at = SIFT_SUBFRAMES  # … at which they are sifted next
        self.times_kept = times_kept
        self._times_held = 0  # RAWX heads and NAV-PVT rows held
        self._times_sift_at = SIFT_TIMES

    def add_rawx(self, data: np.ndarray, payload: np.ndarray, numbers: np.ndarray) -> None:
        head = _records(data, payload, _RAWX_HEAD)
        count = head["numMeas"].astype(np.int64)
        self.heads.append({"rcvTow": head["rcvTow"].astype(np.float64), "week": head["week"].astype(np.int64),
                           "leapS": head["leapS"].astype(np.int64), "numMeas": count, "message": numbers})  # fmt: skip
        self._held_times(head.size)
        if not self.measurements:
            return
        first = np.repeat(payload + 16 - 32 * np.concatenate([[0], np.cumsum(count)[:-1]]), count)
        meas = _records(data, first + 32 * np.arange(int(count.sum())), _RAWX_MEAS)
        each = np.repeat(np.arange(head.size), count)
        i64 = lambda a: a.astype(np.int64)  # noqa: E731
        self.rawx.append({
            "rcvTow": head["rcvTow"][each].astype(np.float64), "week": i64(head["week"][each]),
            "leapS": i64(head["leapS"][each]), "prMes": meas["prMes"].astype(np.float64),
            "cpMes": meas["cpMes"].astype(np.float64), "doMes": meas["doMes"].astype(np.float64),
            "gnssId": i64(meas["gnssId"]), "svId": i64(meas["svId"]), "sigId": i64(meas["sigId"]),
            "freqId": i64(meas["freqId"]), "locktime": i64(meas["locktime"]), "cno": i64(meas["cno"]),
            "prStd": i64(meas["prStdev"] & 0x0F), "cpStd": i64(meas["cpStdev"] & 0x0F), "doStd": i64(meas["doStdev"] & 0x0F),
            "prValid": i64(meas["trkStat"] & 1), "cpValid": i64(meas["trkStat"] >> 1 & 1), "message": numbers[each],
        })  # fmt: skip

    def add_sfrbx(self, data: np.ndarray, payload: np.ndarray, numbers: np.ndarray) -> None:
        head = data[payload[:, None] + np.arange(5)].astype(np.int64)
        count = head[:, 4]
        words = np.zeros((count.size, int(count.max(initial=0))), np.uint32)  # a row per subframe, zeros past its count
        if words.size:
            row = np.repeat(np.arange(count.size), count)
            col = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
            at = np.repeat(payload + 8, count) + 4 * col
            words[row, col] = data[at[:, None] + np.arange(4)].view("<u4").ravel()
        self.sfrbx.append((head[:, 0], head[:, 1], head[:, 2], count, words, numbers))
        self._held += count.size
        if self.subframes_kept is not None and self._held >= self._sift_at:
            self._sift()

    def _sift(self) -> None:
        """Keep only the subframes ``subframes_kept`` names: the memory of what can still change the orbits, not of
        the log (sifted again once the rows held have doubled, so a log's subframes are sifted O(log) times each)."""
        table = self.sfrbx_table()
        keep = np.asarray(self.subframes_kept(table), bool)
        words = table[[c for c in table.columns if c.startswith("w")]].to_numpy(np.uint32)[keep]
        ids = tuple(table[c].to_numpy(np.int64)[keep] for c in SFRBX_COLUMNS[:4])  # gnssId, svId, sigId, n_words
        self.sfrbx = [(*ids, words, table["message"].to_numpy(np.int64)[keep])]  # (add_sfrbx's layout)
        self._held = int(keep.sum())
        self._sift_at = max(SIFT_SUBFRAMES, 2 * self._held)

    def sfrbx_table(self) -> pd.DataFrame:
        """The subframes held, one table (:data:`SFRBX_COLUMNS`, then the words ``w0`` …)."""
        if not self.sfrbx:
            return pd.DataFrame(columns=list(SFRBX_COLUMNS))
        columns = list(zip(*self.sfrbx))
        width = max(w.shape[1] for w in columns[4])
        words = np.concatenate([np.pad(w, ((0, 0), (0, width - w.shape[1]))) for w in columns[4]])
        return pd.DataFrame({"gnssId": np.concatenate(columns[0]), "svId": np.concatenate(columns[1]),
                             "sigId": np.concatenate(columns[2]), "n_words": np.concatenate(columns[3]),
                             "message": np.concatenate(columns[5]), **{f"w{i}": words[:, i] for i in range(width)}})  # fmt: skip

    def add_pvt(self, data: np.ndarray, payload: np.ndarray, numbers: np.ndarray) -> None:
        r = _records(data, payload, _PVT)
        i64 = lambda a: a.astype(np.int64)  # noqa: E731
        self.pvt.append({
            "year": i64(r["year"]), "month": i64(r["month"]), "day": i64(r["day"]), "hour": i64(r["hour"]),
            "minute": i64(r["minute"]), "second": i64(r["second"]), "nano": i64(r["nano"]), "fix_type": i64(r["fix_type"]),
            "lat_deg": r["lat"] / 1e7, "lon_deg": r["lon"] / 1e7, "height_m": r["height"] / 1000.0, "speed_mps": r["g_speed"] / 1000.0,
            "h_acc_m": r["h_acc"] / 1000.0, "speed_acc_mps": r["s_acc"] / 1000.0, "n_sv": i64(r["n_sv"]), "message": numbers,
        })  # fmt: skip
        self._held_times(r.size)

    def _held_times(self, n: int) -> None:
        self._times_held += n
        if self.times_kept is not None and self._times_held >= self._times_sift_at:
            self._sift_times()

    def _sift_times(self) -> None:
        """Keep only the RAWX heads and NAV-PVT rows ``times_kept`` names (given the subframes held), and every NAV-PVT
        row without a date, which the end of the reading counts (or refuses); sifted again once doubled."""
        heads, pvt = self.heads_table(), self.pvt_table()
        keep_heads, keep_pvt = (np.asarray(k, bool) for k in self.times_kept(heads, pvt, self.sfrbx_table()))
        keep_pvt = keep_pvt | ~_dated(pvt)
        self.heads = [{c: heads[c].to_numpy()[keep_heads] for c in HEAD_COLUMNS}]
        self.pvt = [{c: pvt[c].to_numpy()[keep_pvt] for c in PVT_COLUMNS}]
        self._times_held = int(keep_heads.sum() + keep_pvt.sum())
        self._times_sift_at = max(SIFT_TIMES, 2 * self._times_held)

    def rawx_table(self) -> pd.DataFrame:
        """The RAWX measurements added so far, one table."""
        if not self.rawx:
            return pd.DataFrame(columns=[*RAWX_COLUMNS, "message"])
        return pd.DataFrame({c: np.concatenate([b[c] for b in self.rawx]) for c in (*RAWX_COLUMNS, "message")})

    def frames(self) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
        return self.rawx_table(), self.sfrbx_table(), self.pvt_table(), self.heads_table()

    def heads_table(self) -> pd.DataFrame:
        """The RAWX heads added so far (:data:`HEAD_COLUMNS`), one table."""
        if not self.heads:
            return pd.DataFrame({c: np.zeros(0, np.float64 if c == "rcvTow" else np.int64) for c in HEAD_COLUMNS})
        return pd.DataFrame({c: np.concatenate([b[c] for b in self.heads]) for c in HEAD_COLUMNS})

    def pvt_table(self) -> pd.DataFrame:
        """The NAV-PVT rows added so far, one table."""
        if not self.pvt:
            return pd.DataFrame(columns=list(PVT_COLUMNS))
        return pd.DataFrame({c: np.concatenate([b[c] for b in self.pvt]) for c in PVT_COLUMNS})


def read_ubx(path: str, strict: bool = False, block_bytes: int = 1 << 20, measurements: bool = True,
             subframes_kept=None, times_kept=None) -> UbxRead:  # fmt: skip
    """The RAWX, SFRBX and PVT messages of a UBX (or mixed UBX/NMEA/RTCM) log, read ``block_bytes`` at a time.
    ``measurements`` False: the RAWX measurements are not kept (``rawx`` empty; ``rawx_heads`` still one row per
    message): what a long log's first pass needs (its navigation data and times), the measurements read by
    :func:`iter_rawx` after. ``subframes_kept``: a function of a table of subframes (the ``sfrbx`` layout, in log
    order) naming the rows that can still change what is made of them
    (:func:`tollcli.gnss.ubx_measurements.sfrbx_kept`: the orbits); the subframes are sifted through it as they are
    read, and ``sfrbx`` holds only those kept (the reader knows nothing of what they mean). ``times_kept``: likewise a
    function of the RAWX heads, the NAV-PVT rows and the subframes held giving the heads and NAV-PVT rows to keep
    (:func:`tollcli.gnss.ubx_measurements.times_kept`: what the orbits and the check for measurements read); with both,
    a first pass keeps what its orbits need, not what the log's length brings."""
    tables = _Tables(measurements, subframes_kept, times_kept)
    stats = ReadStats(source=str(path), protocol="UBX messages")
    for _ in _frames_into(path, strict, block_bytes, tables, stats):
        pass
    rawx, sfrbx, pvt, heads = tables.frames()
    n_bad = stats.bad_checksum + stats.malformed
    dated = _dated(pvt)
    if not dated.all():  # a damaged date (year 60000) is no date: the row is dropped, and counted
        if strict:
            raise DataError(f"{path}: UBX message {int(pvt['message'][~dated].iloc[0])}: NAV-PVT with an impossible date")
        n_bad += int((~dated).sum())
        pvt = pvt[dated].reset_index(drop=True)
    return UbxRead(rawx, sfrbx, pvt, stats.sentences, n_bad, heads)


def iter_rawx(path: str, strict: bool = False, block_bytes: int = 1 << 20, with_pvt: bool = False):
    """The RXM-RAWX measurements of a UBX log (the table :func:`read_ubx` makes), a block of frames at a time: the
    rows of each block as a table (blocks without one are passed over), in file order; joined, ``read_ubx``'s.
    ``with_pvt``: (measurements, NAV-PVT) of each block with either, the NAV-PVT table :func:`read_ubx` makes (its
    rows with an impossible date dropped: the log's first pass counted them, or refused them with ``strict``)."""
    tables = _Tables()
    for _ in _frames_into(path, strict, block_bytes, tables, ReadStats(), only=(RXM_RAWX, NAV_PVT) if with_pvt else (RXM_RAWX,)):
        if with_pvt and (tables.rawx or tables.pvt):
            pvt = tables.pvt_table()
            yield tables.rawx_table(), pvt[_dated(pvt)].reset_index(drop=True)
        elif tables.rawx:
            yield tables.rawx_table()
        tables.rawx, tables.heads, tables.pvt = [], [], []  # (a block's rows once: the memory of one block)


def _dated(pvt: pd.DataFrame) -> np.ndarray:
    """(n,) the NAV-PVT rows whose date is one (a damaged one, year 60000, is none)."""
    return plausible_date(*(pvt[c].to_numpy(np.int64) for c in ("year", "month", "day", "hour", "minute", "second")))


def _frames_into(path: str, strict: bool, block_bytes: int, tables: _Tables, stats: ReadStats, only: tuple | None = None):
    """The frames of ``path`` of the messages read (``only`` those) added to ``tables``, yielding after each block;
    ``stats`` counts the frames, and as ``malformed`` also the messages whose length is not what their counts say."""
    try:
        stream = open(path, "rb")  # noqa: SIM115 - closed below
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot open ({exc.strerror})") from None
    messages = [m for m in _MESSAGES if only is None or m[0] in only]
    with stream:
        for block in iter_frame_blocks(stream, str(path), stats, strict, block_bytes):
            data = np.frombuffer(block.buf, np.uint8)
            kind = block.classes.astype(np.int64) * 256 + block.ids
            length = block.ends - block.starts - 8
            payload = block.starts + 6
            numbers = block.first_number + np.arange(block.starts.size, dtype=np.int64)
            for (cls, ident), name, fits, add in messages:
                these = np.flatnonzero(kind == cls * 256 + ident)
                if not these.size:
                    continue
                good = fits(data, payload[these], length[these])
                for k in these[~good].tolist():
                    if strict:
                        raise DataError(f"{path}: UBX message {int(numbers[k])}: {name} of {int(length[k])} bytes, not what its counts say")
                    stats.malformed += 1
                these = these[good]
                if these.size:
                    add(tables, data, payload[these], numbers[these])
            yield
    if stats.sentences == 0:
        raise DataError(f"{path}: no UBX messages")


def _count_fits(at: int, head: int, each: int):
    """A message whose length must be ``head`` + ``each`` × the count at payload byte ``at``."""
    def fits(data: np.ndarray, payload: np.ndarray, length: np.ndarray) -> np.ndarray:
        count = data[np.minimum(payload + at, data.size - 1)].astype(np.int64)
        return (length >= head) & (length == head + each * count)

    return fits


#: the messages read: (class, id), name, whether a frame's length fits, and how its frames are added to the tables
_MESSAGES = (
    (RXM_RAWX, "RXM-RAWX", _count_fits(11, 16, 32), _Tables.add_rawx),
    (RXM_SFRBX, "RXM-SFRBX", _count_fits(4, 8, 4), _Tables.add_sfrbx),
    (NAV_PVT, "NAV-PVT", lambda data, payload, length: length >= PVT_MIN_LENGTH, _Tables.add_pvt),
)
