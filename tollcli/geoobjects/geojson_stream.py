"""A GeoJSON FeatureCollection read feature by feature, in blocks of the file, with its SHA-256.

``json.load`` of a national network (437 MB for 150 000 geo-objects) holds the whole text and every coordinate as a
Python float in lists — 3 GB. Here the file is read 8 MiB at a time, each feature decoded on its own
(``json.JSONDecoder.raw_decode``) and, a block of features at a time, its coordinates made into a shapely geometry
(:func:`tollcli.spatial.feature_geometries`: the same numbers, bit for bit), so only the properties and the
geometries are kept. The bytes are hashed as they are read: the digest is of exactly the bytes decoded.
"""

from __future__ import annotations

import codecs
import contextlib
import gc
import hashlib
import json
import re

from tollcli.errors import DataError, UsageError
from tollcli.spatial import feature_geometries, features_of, unclosed_ring

READ_BYTES = 8 << 20
BLOCK = 2000  # features made into geometries at a time
_SPACE = re.compile(r"[ \t\n\r]*")


@contextlib.contextmanager
def gc_paused():
    """Python's cycle collector off for a while: parsing or writing a national network makes millions of lists and
    dicts and no cycles, and a collection every few thousand of them, each over all of them, costs more than the work
    (6× on the GeoJSON coordinates)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


#: the longest one feature's text may be (characters, ≈ 2 million vertices): decoded, its coordinates take ~12 times
#: that (a ring of 10 million vertices, 230 MB of text, took 2.7 GB)
MAX_FEATURE_CHARS = 64_000_000


class _Text:
    """The file's text, decoded block by block; ``buf[pos:]`` is what is not consumed yet."""

    def __init__(self, fh, digest):
        self.fh, self.digest = fh, digest
        self.decoder = codecs.getincrementaldecoder("utf-8")()
        self.buf, self.pos, self.offset, self.eof = "", 0, 0, False

    def more(self) -> bool:
        """Read the next block (False at the end of the file)."""
        if self.eof:
            return False
        data = self.fh.read(READ_BYTES)
        self.digest.update(data)
        self.eof = not data
        if self.pos > READ_BYTES:  # drop what is consumed, now and then (not a copy per feature)
            self.offset += self.pos
            self.buf, self.pos = self.buf[self.pos :], 0
        self.buf += self.decoder.decode(data, final=self.eof)
        return True

    def _too_long(self, path: str) -> DataError:
        return DataError(f"{path}: a feature at character {self.offset + self.pos} is longer than {MAX_FEATURE_CHARS:,} "
                         f"characters of text (millions of vertices): simplify it or cut it into sections")

    def skip_space(self) -> str:
        """The next character that is not white space ('' at the end)."""
        while True:
            self.pos = _SPACE.match(self.buf, self.pos).end()
            if self.pos < len(self.buf) or not self.more():
                return self.buf[self.pos : self.pos + 1]

    def expect(self, char: str, path: str) -> None:
        if self.skip_space() != char:
            raise DataError(f"{path}: not a GeoJSON FeatureCollection (expected {char!r} at character {self.offset + self.pos})")
        self.pos += 1

    def value(self, decoder: json.JSONDecoder, path: str):
        """The next JSON value (reading more of the file while it is cut short; one longer than
        :data:`MAX_FEATURE_CHARS` is refused: its decoded coordinates would take ~12 times its text)."""
        self.skip_space()
        while True:
            try:
                value, end = decoder.raw_decode(self.buf, self.pos)
            except json.JSONDecodeError as exc:
                if len(self.buf) - self.pos > MAX_FEATURE_CHARS:
                    raise self._too_long(path) from None
                if self.more():
                    continue
                raise DataError(f"{path}: not a GeoJSON file ({exc.msg} at character {self.offset + exc.pos})") from None
            except RecursionError:
                raise DataError(f"{path}: not a GeoJSON file (nested too deeply)") from None
            except ValueError as exc:  # an integer of over 4 300 digits
                raise DataError(f"{path}: not a GeoJSON file ({str(exc).split(';')[0]})") from None
            if end == len(self.buf) and not self.eof and self.more():  # a number may go on in the next block
                continue
            if end - self.pos > MAX_FEATURE_CHARS:
                raise self._too_long(path)
            self.pos = end
            return value


def stream_features(path: str, keep: frozenset[str] | None = None) -> tuple[list[dict], str]:
    """The features of a GeoJSON FeatureCollection — each ``{"type", "properties", "geometry"}`` with the geometry a
    shapely one (a feature whose geometry cannot be read keeps its own, to say why) — and the file's SHA-256.
    ``keep``: the only properties kept (None: all)."""
    doc, digest = stream_collection(path, keep)
    return doc["features"], digest


def stream_collection(path: str, keep: frozenset[str] | None = None, geometry: bool = True) -> tuple[dict, str]:
    """The FeatureCollection's members, its ``features`` as :func:`stream_features` gives them (``geometry``
    False: their properties only), and the file's SHA-256."""
    digest = hashlib.sha256()
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, expected a geo-object file (GeoJSON)") from None
    except OSError as exc:
        raise DataError(f"{path}: not a GeoJSON file ({exc.strerror})") from None
    decoder = json.JSONDecoder()
    members: dict = {}
    features: list[dict] = []
    try:
        with fh:
            text = _Text(fh, digest)
            text.expect("{", path)
            while text.skip_space() != "}":
                if members or features:
                    text.expect(",", path)
                key = text.value(decoder, path)
                text.expect(":", path)
                if key == "features" and text.skip_space() == "[":
                    text.pos += 1
                    features += _features(text, decoder, path, keep, geometry)
                    members["features"] = None
                else:
                    members[key] = text.value(decoder, path)
            text.pos += 1
            if text.skip_space() != "":
                raise DataError(f"{path}: not a GeoJSON file (extra data at character {text.offset + text.pos})")
    except (UnicodeDecodeError, TypeError) as exc:
        raise DataError(f"{path}: not a GeoJSON file ({exc})") from None
    if members.get("features", 0) is None:
        members["features"] = features
    features_of(members, path)  # a WGS-84 FeatureCollection, or the error saying what it is not
    return members, digest.hexdigest()


def _features(text: _Text, decoder: json.JSONDecoder, path: str, keep: frozenset[str] | None, geometry: bool) -> list[dict]:
    """The features of the array the text is in (after its '['), made into geometries a block at a time."""
    out: list[dict] = []
    block: list = []
    while text.skip_space() != "]":
        if out or block:
            text.expect(",", path)
        block.append(text.value(decoder, path))
        if len(block) == BLOCK:
            out += _slim(block, keep, geometry)
            block = []
    text.pos += 1
    return out + _slim(block, keep, geometry)


def _slim(block: list, keep: frozenset[str] | None, geometry: bool = True) -> list:
    """Features with their coordinates made into shapely geometries (a feature whose geometry cannot be read, or
    that is no feature, kept as it is: check says why)."""
    if not geometry:
        return [{"type": f.get("type"), "properties": f.get("properties")} if isinstance(f, dict) else f for f in block]
    geoms = feature_geometries(block, "Polygon")
    out = []
    for feature, geom in zip(block, geoms):
        if geom is None or not isinstance(feature, dict) or unclosed_ring(feature):  # (shapely would close the ring: check says why)
            out.append(feature)
        else:
            props = feature.get("properties")
            if keep is not None and isinstance(props, dict):
                props = {k: v for k, v in props.items() if k in keep}
            out.append({"type": feature.get("type"), "properties": props, "geometry": geom})
    return out
