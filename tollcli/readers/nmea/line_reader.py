"""The per-line NMEA reader: what each line is, and the counts of what happened to every line.

:func:`classify_line` verifies one raw line (checksum, address) and :func:`feed_lines`
decodes a block of lines one at a time into an :class:`~tollcli.readers.nmea.assembler.EpochAssembler`.
This is the reference path: the bulk reader hands it the lines out of the ordinary and is
tested against it on every real log. :class:`ReadStats` counts every line of a log.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tollcli.errors import DataError
from tollcli.readers.nmea.assembler import EpochAssembler
from tollcli.readers.nmea.fields import checksum

ANDROID_PREFIX = "NMEA,"


@dataclass
class ReadStats:
    """What happened to every line of a log."""

    source: str = ""
    protocol: str = "NMEA sentences"  # what ``sentences`` counts (UBX messages, gpsd JSON reports)
    lines: int = 0  # lines (UBX: frames)
    bytes_read: int = 0  # bytes a binary reader read (UBX: a file of bytes with no frame in them is not empty)
    sentences: int = 0  # checksum-verified NMEA sentences (UBX frames, JSON reports)
    decoded: int = 0  # of which decoded into epochs
    unused: int = 0  # valid sentences of types the reader does not use (proprietary, AIS, ...)
    comments: int = 0
    blank: int = 0
    bad_checksum: int = 0
    no_checksum: int = 0
    malformed: int = 0
    not_nmea: int = 0
    discarded_text: int = 0  # lines whose sentence was read but text before it was dropped (junk, a glued sentence)
    epochs: int = 0
    per_line_epochs: int = 0  # of which assembled line by line (the bulk reader's slow path; all with the reference reader)
    satellite_rows: int = 0
    undated_epochs: int = 0
    untimed_reports: int = 0  # gpsd fixes (TPV) without a time: skipped (no epoch can be placed without one)
    first_problem: str = ""
    unused_types: dict[str, int] = field(default_factory=dict)

    @property
    def skipped(self) -> int:
        """Lines that could not be used: the count ``--strict`` refuses."""
        return self.bad_checksum + self.no_checksum + self.malformed + self.not_nmea

    def summary(self) -> str:
        """One line for stderr."""
        parts = [
            f"{self.lines} lines",
            f"{self.sentences} {self.protocol}",
            f"{self.epochs} epochs",
            f"{self.satellite_rows} satellite rows",
        ]
        skipped = [
            (self.bad_checksum, "bad checksum"),
            (self.no_checksum, "no checksum"),
            (self.malformed, "malformed"),
            (self.not_nmea, "not NMEA"),
        ]
        detail = ", ".join(f"{n} {what}" for n, what in skipped if n)
        text = f"{self.source}: " + ", ".join(parts)
        if self.skipped:
            text += f"; skipped {self.skipped} lines ({detail})"
        if self.discarded_text:
            text += f"; text before the sentence dropped on {self.discarded_text} lines"
        if self.undated_epochs:
            text += f"; {self.undated_epochs} epochs without a date (no RMC/ZDA; use --date)"
        if self.untimed_reports:
            text += f"; skipped {self.untimed_reports} fixes without a time"
        if self.per_line_epochs:
            text += f"; {self.per_line_epochs} epochs read line by line"
        return text

    def as_dict(self) -> dict:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out["skipped"] = self.skipped
        return out



HANDLED_TYPES = frozenset(EpochAssembler().handled_types())


#: ``classify_line``'s word for a usable sentence that had text before it
DISCARDED = "text before the sentence discarded"


def classify_line(line: str) -> tuple[str, str, str, list[str]]:
    """What one raw line is: ``(kind, why, address, fields)``.

    ``kind``: ``blank``, ``comment``, ``not_nmea``, ``no_checksum``, ``bad_checksum``
    (``why`` says what is wrong), ``unused`` (a valid sentence the reader does not
    use) or ``sentence`` (a valid sentence of a type the assembler reads; ``fields``
    are those after the address). For those two, ``why`` is :data:`DISCARDED` when text before the
    sentence (binary junk, another sentence glued on) was dropped, else empty.
    """
    line = line.strip()
    if not line:
        return "blank", "", "", []
    if line[0] == "#":
        return "comment", "", "", []
    if line.startswith(ANDROID_PREFIX):
        line = line[len(ANDROID_PREFIX) :]
    star = line.rfind("*")
    end = star if star >= 0 else len(line)
    start = max(line.rfind("$", 0, end), line.rfind("!", 0, end))  # '!': encapsulated (AIS) sentences
    if start < 0:
        return "not_nmea", "not an NMEA sentence", "", []
    if star < 0:
        return "no_checksum", "no checksum (truncated sentence?)", "", []
    body = line[start + 1 : star]
    try:
        expected = int(line[star + 1 : star + 3], 16)
    except ValueError:
        return "no_checksum", "unreadable checksum", "", []
    got = checksum(body)
    if got != expected:
        return "bad_checksum", f"bad checksum (*{expected:02X} given, {got:02X} computed)", "", []
    fields = body.split(",")
    address = fields[0]
    dropped = DISCARDED if start > 0 else ""
    if len(address) != 5 or address[0] == "P" or address[2:] not in HANDLED_TYPES:
        return "unused", dropped, address, []
    return "sentence", dropped, address, fields[1:]


def feed_lines(lines: list[str], asm: EpochAssembler, stats: ReadStats, strict: bool, name: str) -> None:
    """Classify, verify and decode one block of lines, one line at a time (the reference path)."""
    line_no = stats.lines
    for line in lines:
        line_no += 1
        kind, why, address, fields = classify_line(line)
        if kind == "sentence":
            stats.sentences += 1
            try:
                asm.feed(address[:2], address[2:], fields, line_no)
            except (ValueError, IndexError, OverflowError) as exc:
                problem(stats, "malformed", line_no, f"malformed {address}: {exc}", strict, name)
                continue
            stats.decoded += 1
            stats.discarded_text += why == DISCARDED  # the sentence was used; text before it was not
        elif kind == "unused":
            stats.sentences += 1
            stats.unused += 1
            stats.discarded_text += why == DISCARDED
            stats.unused_types[address] = stats.unused_types.get(address, 0) + 1
        elif kind == "blank":
            stats.blank += 1
        elif kind == "comment":
            stats.comments += 1
        else:
            problem(stats, kind, line_no, why, strict, name)
    stats.lines = line_no


def problem(stats: ReadStats, kind: str, line_no: int, why: str, strict: bool, name: str) -> None:
    if strict:
        raise DataError(f"{name}:{line_no}: {why}")
    setattr(stats, kind, getattr(stats, kind) + 1)
    if not stats.first_problem:
        stats.first_problem = f"line {line_no}: {why}"
