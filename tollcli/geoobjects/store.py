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
only; a cache that cannot be written is silently skipped; a damaged store is compiled again.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

from tollcli.cache import cache_dir
from tollcli.geoobjects.compiled import (  # noqa: F401  (section_lengths, tunnel_lengths: re-exported)
    STORE_FORMAT,
    compile_features,
    compile_file,
    section_lengths,
    tunnel_lengths,
)
from tollcli.geoobjects.index import GridIndex, StoredGeometries
from tollcli.errors import DataError
from tollcli.io.sources import file_sha256

#: the slowest traffic a tunnel's GNSS outage is allowed for (7.2 km/h, a congested tunnel), m/s
TUNNEL_MIN_SPEED_MPS = 2.0
FLOAT_COLUMNS = ("hal_m", "length_m", "tunnel_m", "gap_m")
INT_COLUMNS = ("frame", "n_parts", "names_code", "road_class_code")


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
    """A geo-object file (as written by ``tollcli geoobjects build``) ready for recognition: its store memory-mapped,
    compiled first when there is none. ``sha256``: the file's digest when the caller has just computed it (a batch);
    a file compiled here must still have it."""
    try:
        digest = sha256 or file_sha256(path)
    except OSError:
        digest = None  # the compile says why it cannot be read
    folder = store_path(digest) if digest is not None else None
    if folder is not None and folder.is_dir():
        try:
            geo = geoobjects_from_columns(read_store(folder))
            geo.source_sha256, geo.store = digest, folder
            return geo
        except (OSError, ValueError, KeyError, EOFError, TypeError, json.JSONDecodeError):
            pass  # a damaged store: compile again
    spill = _spill_beside(folder) if folder is not None else None
    try:
        columns, parsed_digest = compile_file(path, spill)
        if digest is not None and parsed_digest != digest:
            raise DataError(f"{path}: the file changed while it was read (SHA-256 {parsed_digest[:12]}…, expected {digest[:12]}…)")
    except BaseException:
        if spill is not None:
            shutil.rmtree(spill.folder, ignore_errors=True)
        raise
    stored = write_store(folder, columns) if folder is not None else None
    geo = geoobjects_from_columns(read_store(stored) if stored is not None else columns)
    geo.source_sha256, geo.store = parsed_digest, stored  # hashed once, for the store's key and for the invoice
    return geo


def _spill_beside(folder: Path) -> "_Spill | None":
    """A temporary store folder beside ``folder`` to compile into (None: the cache cannot be written)."""
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        return _Spill(Path(tempfile.mkdtemp(dir=folder.parent, suffix=".tmp")))
    except OSError:
        return None


def precompile(features: list, path: str, digest: str) -> Path | None:
    """The store of a file just written from ``features`` (which passed ``geoobjects check``) under its SHA-256
    ``digest``: the store its first ``process`` would make, made now (None: the cache is off or not writable)."""
    folder = store_path(digest)
    if folder is None or folder.is_dir():
        return folder
    spill = _spill_beside(folder)
    if spill is None:
        return None
    try:
        compile_features(features, path, checked=True, columns=spill)
    except BaseException:
        shutil.rmtree(spill.folder, ignore_errors=True)
        raise
    return write_store(folder, spill)


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
                pass  # kept in memory: write_store tries again, and says nothing if it cannot
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
            raise ValueError(f"store column {name}: {len(columns[name])} rows for {n} geo-objects")
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
    return GeoObjects(ids, names, road_class, columns["hal_m"], metric, strings["crs"], GridIndex(columns, search),
                      tuple(strings["frames"]), columns["frame"], None, columns["length_m"], columns["tunnel_m"], axes,
                      columns["gap_m"], columns["n_parts"], directed)  # fmt: skip


_EMPTY_LINE_WKB = len(shapely.to_wkb(shapely.LineString()))


def write_store(folder: Path, columns: dict) -> Path | None:
    """Write the store's arrays into ``folder`` atomically (a temporary folder renamed); None when it cannot be
    written (the cache is then skipped) — a folder another process has just written is kept."""
    tmp = columns.folder if isinstance(columns, _Spill) else None
    try:
        if tmp is None:
            folder.parent.mkdir(parents=True, exist_ok=True)
            tmp = Path(tempfile.mkdtemp(dir=folder.parent, suffix=".tmp"))
        for name, value in columns.items():
            if name == "strings":
                (tmp / "strings.json").write_text(json.dumps(value, ensure_ascii=False), encoding="utf-8")
            elif not (isinstance(value, np.memmap) and Path(value.filename).parent == tmp):  # not already there
                np.save(tmp / f"{name}.npy", np.ascontiguousarray(value), allow_pickle=False)
        if folder.is_dir():  # a damaged store: set aside (processes that mapped its files keep them until they end)
            aside = Path(tempfile.mkdtemp(dir=folder.parent, suffix=".old"))
            os.replace(folder, aside / folder.name)
            shutil.rmtree(aside, ignore_errors=True)
        os.replace(tmp, folder)
        return folder
    except OSError:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        return folder if folder.is_dir() else None


def read_store(folder: Path) -> dict:
    """The store's arrays, memory-mapped (read-only: shared by every process that maps them)."""
    columns: dict = {"strings": json.loads((folder / "strings.json").read_text(encoding="utf-8"))}
    for file in folder.glob("*.npy"):
        columns[file.stem] = np.load(file, mmap_mode="r", allow_pickle=False)
    return columns


