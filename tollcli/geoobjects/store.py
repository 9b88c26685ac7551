"""Load a geo-object file for charging: compile it once into a store of plain arrays, then memory-map that store.

A geo-object file changes rarely and is read for every log. Compiling it parses the GeoJSON (plain single-ring
polygons in bulk, anything else feature by feature), checks every feature (a file that ``tollcli geoobjects check``
rejects is refused, never compiled), projects each polygon to its own metric frame (its ``crs_metric``; a feature
without one gets :func:`tollcli.spatial.local_frame`) and, for the spatial index, to one search CRS for the file.
The store is a folder of numpy files in ``$TOLLCLI_CACHE_DIR/geoobjects/<SHA-256 of the file>.v<STORE_FORMAT>/``
(default cache ``~/.cache/tollcli``): per geo-object its HAL, lengths, frame, number of parts and whether it is a
directed carriageway; the polygons in their own frames (and, with several frames, in the search CRS) and the
carriageways' axes as WKB (every coordinate bit for bit: invoices never depend on the store); the boxes and a grid
over them (:mod:`tollcli.geoobjects.index`); ids, names and road classes as JSON.

Loading memory-maps the arrays: nothing is parsed, the workers of a batch (and Dask workers on one host) share the
pages, and a run decodes only the polygons of the geo-objects near its track — its cost grows with the drive, not
with the network. ``tollcli geoobjects build`` compiles what it writes, ``tollcli geoobjects compile`` a file made
elsewhere; ``process`` compiles a file met for the first time. ``TOLLCLI_CACHE_DIR=off`` keeps the store in memory
only; a cache that cannot be written is silently skipped. Every file of a store is checked against the digests of its
manifest before use (:mod:`tollcli.geoobjects.store_files`); a store that fails is compiled again, said on stderr.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

from tollcli.cache import CacheNotUsed, cache_dir, trusted_folder
from tollcli.geoobjects.compiled import (  # noqa: F401  (section_lengths, tunnel_lengths: re-exported)
    STORE_FORMAT,
    compile_features,
    compile_file,
    section_lengths,
    tunnel_lengths,
)
from tollcli.geoobjects.index import GridIndex, StoredGeometries
from tollcli.geoobjects.store_files import StoreRejected, TempStore, manifest_of, manifest_sha256, put_in_place, read_verified
from tollcli.errors import DataError
from tollcli.geoobjects.check import MAX_LENGTH_M
from tollcli.spatial import HAL_MAX_M
from tollcli.io.sources import file_sha256

#: the slowest traffic a tunnel's GNSS outage is allowed for (7.2 km/h, a congested tunnel), m/s
TUNNEL_MIN_SPEED_MPS = 2.0
FLOAT_COLUMNS = ("hal_m", "length_m", "tunnel_m", "gap_m")
INT_COLUMNS = ("frame", "n_parts", "names_code", "road_class_code", "environment_code")


@dataclass
class GeoObjects:
    ids: np.ndarray
    names: np.ndarray
    road_class: np.ndarray
    hal_m: np.ndarray
    polygons: StoredGeometries  # each in its own metric frame, frames[frame[i]]; decoded when first indexed
    crs: str  # the search CRS of the file: the spatial index and coarse queries (bounding boxes, reachability)
    index: GridIndex  # over the boxes in the search CRS; answers as shapely.STRtree.query does
    frames: tuple[str, ...] = ()
    frame: np.ndarray | None = None  # per geo-object: index into frames
    source_sha256: str | None = None  # SHA-256 of the file's bytes these were made from (None: not from a file)
    #: per geo-object: the section's length, ground metres (``section_length_m``, else ``length_m``; NaN: none given),
    #: what per-km rates charge
    length_m: np.ndarray | None = None
    #: per geo-object: metres of it in tunnels (``tunnel_m``; the whole section when only ``tunnel`` is set; 0: none),
    #: where no GNSS reaches: passages and findings expect the gap
    tunnel_m: np.ndarray | None = None
    #: per geo-object: its axis in its own metric frame when it is a carriageway told apart from the opposite one by the
    #: direction of travel (``carriageways.py``; decoded when first indexed), else an empty line; None: no carriageway
    axes: StoredGeometries | None = None
    #: per geo-object: the longest stretch of its section between two of its parts (``gap_m``; 0: one part), m — a
    #: passage spans it without a fix inside
    gap_m: np.ndarray | None = None
    #: per geo-object: how many polygons (parts) it has
    n_parts: np.ndarray | None = None
    #: per geo-object: counts a position only in its direction of travel (has an axis)
    directed_mask: np.ndarray | None = None
    #: the store folder the arrays are mapped from (None: compiled in memory)
    store: Path | None = None
    #: SHA-256 of the store's manifest (the digests of its arrays): what the invoice records beside the file's
    store_sha256: str | None = None
    #: per geo-object: the environment the operator declared its road runs in ('open', 'urban'; '' none): the error
    #: model the ``model`` level takes there (integrity/environment.py: with_declared_environment)
    environment: np.ndarray | None = None

    def directed(self) -> np.ndarray:
        """Which geo-objects count a position only in their direction of travel."""
        return self.directed_mask if self.directed_mask is not None else np.zeros(len(self.ids), bool)

    def tunnel_lengths_m(self) -> np.ndarray:
        return self.tunnel_m if self.tunnel_m is not None else np.zeros(len(self.ids))

    def tunnel_times_s(self) -> np.ndarray:
        """Per geo-object: how long its tunnels may keep GNSS away, s (their length at ``TUNNEL_MIN_SPEED_MPS``)."""
        return self.tunnel_lengths_m() / TUNNEL_MIN_SPEED_MPS

    def gap_times_s(self) -> np.ndarray:
        """Per geo-object: how long a passage may spend between two of its parts, s (tunnels and the longest gap
        between parts at ``TUNNEL_MIN_SPEED_MPS``: a slow vehicle crossing the stretch cut out is one passage)."""
        gaps = self.gap_m if self.gap_m is not None else np.zeros(len(self.ids))
        return (self.tunnel_lengths_m() + gaps) / TUNNEL_MIN_SPEED_MPS


def load_geoobjects(path: str, sha256: str | None = None) -> GeoObjects:
    """A geo-object file (as written by ``tollcli geoobjects build``) ready for recognition: its store memory-mapped
    when one verifies (:mod:`tollcli.geoobjects.store_files`), compiled first when there is none or it fails its check
    (said once on stderr). ``sha256``: the file's digest when the caller has just computed it (a batch); a file
    compiled here must still have it."""
    try:
        digest = sha256 or file_sha256(path)
    except OSError:
        digest = None  # the compile says why it cannot be read
    folder = store_path(digest) if digest is not None else None
    if folder is not None and (folder.exists() or folder.is_symlink()):
        try:
            columns, store_digest = read_verified(folder, STORE_FORMAT, digest)
            return _geoobjects(columns, digest, folder, store_digest)
        except StoreRejected as exc:
            warnings.warn(f"geo-object store {folder} not used ({exc}): compiled again", CacheNotUsed, stacklevel=2)
    temp = _temp_beside(folder) if folder is not None else None
    spill = _Spill(temp.folder) if temp is not None else None
    try:
        columns, parsed_digest = compile_file(path, spill)
        if digest is not None and parsed_digest != digest:
            raise DataError(f"{path}: the file changed while it was read (SHA-256 {parsed_digest[:12]}…, expected {digest[:12]}…)")
    except BaseException:
        if temp is not None:
            temp.discard()
        raise
    return _geoobjects_written(folder, temp, columns, parsed_digest)


def _geoobjects_written(folder: Path | None, temp: "TempStore | None", columns: dict, digest: str) -> GeoObjects:
    """Geo-objects of columns just compiled: their store put in place and mapped from there when the cache can be
    written, else (or when the folder cannot be read back) the columns themselves."""
    placed = put_in_place(temp, folder, columns, STORE_FORMAT, digest) if temp is not None else None
    if placed is not None:
        try:
            mapped, store_digest = read_verified(placed[0], STORE_FORMAT, digest)
            return _geoobjects(mapped, digest, placed[0], store_digest)
        except StoreRejected:
            pass  # replaced or removed meanwhile: the columns in memory are the same
    return _geoobjects(columns, digest, None, manifest_sha256(manifest_of(columns, STORE_FORMAT, digest)))


def _geoobjects(columns: dict, digest: str | None, folder: Path | None, store_digest: str) -> GeoObjects:
    geo = geoobjects_from_columns(columns)
    geo.source_sha256, geo.store, geo.store_sha256 = digest, folder, store_digest
    return geo


def _temp_beside(folder: Path) -> "TempStore | None":
    """A temporary store folder beside ``folder`` to compile into (None: the cache cannot be written)."""
    try:
        folder.parent.mkdir(mode=0o700, exist_ok=True)
        if not trusted_folder(folder.parent):
            return None
        return TempStore(folder.parent)
    except OSError:
        return None


def precompile(features: list, path: str, digest: str) -> Path | None:
    """The store of a file just written from ``features`` (which passed ``geoobjects check``) under its SHA-256
    ``digest``: the store its first ``process`` would make, made now (None: the cache is off or not writable)."""
    folder = store_path(digest)
    if folder is None:
        return None
    try:
        read_verified(folder, STORE_FORMAT, digest)
        return folder
    except StoreRejected:
        pass
    temp = _temp_beside(folder)
    if temp is None:
        return None
    try:
        columns = compile_features(features, path, checked=True, columns=_Spill(temp.folder))
    except BaseException:
        temp.discard()
        raise
    placed = put_in_place(temp, folder, columns, STORE_FORMAT, digest)
    return placed[0] if placed is not None else None


class _Spill(dict):
    """Store arrays written to their files in ``folder`` as they are made and mapped back: compiling a national
    network never holds all its WKB in memory."""

    def __init__(self, folder: Path):
        super().__init__()
        self.folder = folder

    def put_blocks(self, name: str, blocks: list[np.ndarray]) -> None:
        """A byte array given in blocks, streamed to its file (never joined in memory)."""
        path = self.folder / f"{name}.npy"
        try:
            with open(path, "wb") as fh:
                np.lib.format.write_array_header_1_0(fh, {"descr": "|u1", "fortran_order": False, "shape": (sum(len(b) for b in blocks),)})
                for block in blocks:
                    fh.write(block.tobytes())
            super().__setitem__(name, np.load(path, mmap_mode="r", allow_pickle=False))
        except OSError:
            super().__setitem__(name, np.concatenate(blocks) if blocks else np.zeros(0, np.uint8))

    def __setitem__(self, name, value):
        if name != "strings":
            try:
                np.save(self.folder / f"{name}.npy", np.ascontiguousarray(value), allow_pickle=False)
                value = np.load(self.folder / f"{name}.npy", mmap_mode="r", allow_pickle=False)
            except OSError:
                pass  # kept in memory: put_in_place tries again, and says nothing if it cannot
        super().__setitem__(name, value)


def store_path(digest: str) -> Path | None:
    """The store folder of a file of this SHA-256 (None: the cache is off)."""
    base = cache_dir()
    return None if base is None else base / "geoobjects" / f"{digest}.v{STORE_FORMAT}"


def geoobjects_from_columns(columns: dict) -> GeoObjects:
    """Geo-objects over the store's arrays (mapped from a store folder, or just compiled)."""
    strings = columns["strings"]
    if strings.get("format") != STORE_FORMAT:
        raise ValueError("store format")
    ids = np.array(strings["ids"], dtype=object)
    n = len(ids)
    for name in (*FLOAT_COLUMNS, *INT_COLUMNS, "metric_ends", "bounds"):
        if len(columns[name]) != n:
            raise StoreRejected(f"store column {name}: {len(columns[name])} rows for {n} geo-objects")
    _check_values(columns, strings)
    metric = StoredGeometries(columns["metric_wkb"], columns["metric_ends"])
    if n and int(metric.ends[-1]) != len(metric.wkb):
        raise ValueError("store: the polygons' bytes are cut short")
    search = StoredGeometries(columns["search_wkb"], columns["search_ends"]) if "search_wkb" in columns else metric
    axes = StoredGeometries(columns["axes_wkb"], columns["axes_ends"]) if "axes_wkb" in columns else None
    directed = np.zeros(n, bool)
    if axes is not None:
        starts = np.r_[0, axes.ends[:-1]]
        directed = (axes.ends - starts) > _EMPTY_LINE_WKB  # an empty line's WKB is 9 bytes: "no axis"
    names = np.array(strings["names"], dtype=object)[np.asarray(columns["names_code"])]
    road_class = np.array(strings["road_class"], dtype=object)[np.asarray(columns["road_class_code"])]
    environment = np.array(strings["environment"], dtype=object)[np.asarray(columns["environment_code"])]
    return GeoObjects(ids, names, road_class, columns["hal_m"], metric, strings["crs"], GridIndex(columns, search),
                      tuple(strings["frames"]), columns["frame"], None, columns["length_m"], columns["tunnel_m"], axes,
                      columns["gap_m"], columns["n_parts"], directed,
                      environment=environment if (environment != "").any() else None)  # fmt: skip


_EMPTY_LINE_WKB = len(shapely.to_wkb(shapely.LineString()))


def _check_values(columns: dict, strings: dict) -> None:
    """StoreRejected unless every value is one a checked geo-object file can give: a HAL in (0, HAL_MAX_M], lengths
    in [0, MAX_LENGTH_M] (a section's may be NaN: none given), finite boxes, codes within their tables."""
    hal = np.asarray(columns["hal_m"])
    if not np.all((hal > 0) & (hal <= HAL_MAX_M)):
        raise StoreRejected(f"a hal_m outside (0, {HAL_MAX_M:g}] m")
    length = np.asarray(columns["length_m"])
    if not np.all(np.isnan(length) | ((length >= 0) & (length <= MAX_LENGTH_M))):
        raise StoreRejected("a length_m outside [0, 1 000 km]")
    for name in ("tunnel_m", "gap_m"):
        if not np.all((np.asarray(columns[name]) >= 0) & (np.asarray(columns[name]) <= MAX_LENGTH_M)):
            raise StoreRejected(f"a {name} outside [0, 1 000 km]")
    if not np.all(np.isfinite(np.asarray(columns["bounds"]))):
        raise StoreRejected("a box that is not finite")
    if not set(strings.get("environment", [])) <= {"", "open", "urban"}:
        raise StoreRejected("an environment that is not declared open or urban")
    for name, table in (("frame", "frames"), ("names_code", "names"), ("road_class_code", "road_class"),
                        ("environment_code", "environment")):  # fmt: skip
        codes = np.asarray(columns[name])
        if codes.size and (codes.min() < 0 or codes.max() >= len(strings[table])):
            raise StoreRejected(f"{name} outside its table")
