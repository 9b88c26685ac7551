"""A seeded mutation fuzzer over a real file of every input kind (part of issue 54): bit flips, truncation, a record
duplicated or two swapped, a number replaced by NaN, infinity, 10⁴⁰⁰ or 400 digits, NUL runs, a 300 kB field; UBX
frames with their checksums recomputed (a flipped payload byte, an edited length). Each case goes through ``info``
and ``integrity`` (or the commands that read it): a documented exit (never 4 or 5), an error in one line, no output
left behind by an error. Road files (GeoJSON, GeoPackage, FlatGeobuf, Shapefile) go through ``geoobjects build``.

``FUZZ_EXAMPLES`` sets the budget (cases in all; CI runs a small fixed set); ``benchmarks/fuzz_nightly.py`` runs
thousands. A case is its kind and number: ``pytest tests/test_fuzz_inputs.py -k 'ubx-17'`` replays it.
"""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest
from conftest import REPO, run_main
from conftest import SHARED_DATA as SHARED

from tollcli.readers.ubx_frames import checksum

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
RURAL = REPO / "samples" / "sim" / "rural-clean"

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "60"))
#: the seed files: kind → (path under ../shared/data, bytes kept from its start (0: all), extra options)
SEEDS = {
    "ubx": ("rtklibexplorer/gnss_1730.ubx", 500_000, ()),
    "ubx-nav": ("gpsd/ublox-neo-m8l.log", 0, ()),
    "gpsd-json": ("gpsd/ac12.log.chk", 0, ()),
    "gsdc-derived": ("gsdc2021/Pixel4_derived.csv", 0, ()),
    "device-gnss": ("gsdc2022/device_gnss.csv", 0, ()),
    "gnsslogger": ("android/pixel6_gnsslogger.txt", 0, ("--nav", str(SHARED / "rinex" / "brdc1190.21n"))),
    "rinex": ("android/pixel6.23o", 0, ("--nav", str(SHARED / "rinex" / "brdc1190.21n"))),
    "rtklib-pos": ("rtklibexplorer/gnss_1730_sf.pos", 0, ()),
    "librsf": ("smartloc/Berlin_Potsdamer_Platz_Input.txt", 400_000, ()),
    "nmea": ("gpsd/ublox-neo-m8n.log", 0, ()),
    "osnma-vector": ("osnma/icd_configuration_1/16_AUG_2023_GST_05_00_01.csv", 300_000,
                     ("--merkle", str(SHARED / "osnma" / "icd_configuration_1" / "OSNMA_MerkleTree.xml"))),
}
#: kinds read by ``osnma`` (a test vector; the u-blox log with a mutated public key), not by info and integrity
OSNMA_KINDS = ("osnma-vector", "osnma-key")
#: what a number token may become
ODD_NUMBERS = (b"NaN", b"nan", b"inf", b"-inf", b"1e400", b"-1e400", b"9" * 400, b"-0", b"", b"0", b"-1", b"1e-320", b"\x00")
DOCUMENTED = {0, 1, 2, 3, 6}  # (6: a batch some of whose logs failed)
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


#: inputs the tool writes and reads back (an invoice for ``verify``/``info``/``--config``, a TOML settings file): made
#: once from the straight-drive sample, then mutated like the receivers' files
WRITTEN = ("invoice", "settings", "truth", "fleet", "roadside", "osnma-key")
#: road files through ``geoobjects build`` (issue 55): the example roads as GeoJSON, GeoPackage, FlatGeobuf and a
#: Shapefile whose .shp, .dbf or .prj is the mutated part
ROADS = ("roads-geojson", "roads-gpkg", "roads-fgb", "roads-shp", "roads-dbf", "roads-prj")
_ROAD_FILES: dict[str, bytes] = {}


def _road_files() -> dict[str, bytes]:
    """The example roads written once in every road-file format (file name → bytes)."""
    if not _ROAD_FILES:
        import tempfile

        import geopandas as gpd

        roads = gpd.read_file(REPO / "geoobjects" / "example-roads.geojson")
        with tempfile.TemporaryDirectory() as tmp:
            roads.to_file(os.path.join(tmp, "roads.gpkg"), driver="GPKG")
            roads.to_file(os.path.join(tmp, "roads.fgb"), driver="FlatGeobuf")
            roads.to_file(os.path.join(tmp, "roads.shp"))
            for name in os.listdir(tmp):
                _ROAD_FILES[name] = open(os.path.join(tmp, name), "rb").read()
        _ROAD_FILES["roads.geojson"] = (REPO / "geoobjects" / "example-roads.geojson").read_bytes()
    return _ROAD_FILES


def _road_target(kind: str) -> str:
    return {"roads-geojson": "roads.geojson", "roads-gpkg": "roads.gpkg", "roads-fgb": "roads.fgb", "roads-shp": "roads.shp",
            "roads-dbf": "roads.dbf", "roads-prj": "roads.prj"}[kind]  # fmt: skip
_WRITTEN_SEEDS: dict[str, bytes] = {}


def _written_seed(kind: str) -> bytes:
    if kind not in _WRITTEN_SEEDS:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            for name, drive in (("invoice", REPO / "samples" / "straight-drive.nmea"), ("rural invoice", RURAL / "drive.nmea")):
                out = os.path.join(tmp, "i.json")
                code, err = run_main("process", str(drive), "--geo", GEO, "--tariff", TARIFF, "-o", out, "-q")
                assert code == 0, err
                _WRITTEN_SEEDS[name] = open(out, "rb").read()
        _WRITTEN_SEEDS["settings"] = (b'date = 2024-05-06\nhal = 40.0\ntc = 5.0\nn_th = 3\nraim = "ss"\npolicy = "raim"\n'
                                      b'vehicle = "TRK 042"\nvehicle_class = "truck"\nsigma = 5.0\np_md = 5e-5\n')  # fmt: skip
        _WRITTEN_SEEDS["truth"] = (RURAL / "truth.csv").read_bytes()  # the rural drive's truth, audited with its invoice
        _WRITTEN_SEEDS["fleet"] = b"vehicle,vehicle_class\nstraight-drive,truck\nTRK-042,car\n"
        _WRITTEN_SEEDS["roadside"] = (b"tag_id,gantry_id,time_utc\nTAG-1,G1,2024-05-06T08:00:30Z\nTAG-1,G2,2024-05-06T08:01:40Z\n"
                                      b"TAG-1,G1,2024-05-06T09:30:00Z\nTAG-9,G2,2024-05-06T08:02:00Z\n")  # fmt: skip
        key = SHARED / "osnma" / "ublox" / "OSNMA_PublicKey_1.xml"
        _WRITTEN_SEEDS["osnma-key"] = key.read_bytes() if key.exists() else b"<xml/>"
    return _WRITTEN_SEEDS[kind]


def _seed(kind: str) -> bytes:
    if kind in WRITTEN:
        return _written_seed(kind)
    if kind in ROADS:
        return _road_files()[_road_target(kind)]
    path, keep, _ = SEEDS[kind]
    data = (SHARED / path).read_bytes()
    return data[:keep] if keep else data


def _ubx_frames(data: bytes) -> list[tuple[int, int]]:
    """(start, length with header and checksum) of the UBX frames of ``data``."""
    frames, i = [], 0
    while (i := data.find(b"\xb5\x62", i)) >= 0 and i + 8 <= len(data):
        n = data[i + 4] | data[i + 5] << 8
        if i + 8 + n <= len(data):
            frames.append((i, 8 + n))
            i += 8 + n
        else:
            i += 2
    return frames


def _mutate_ubx(data: bytes, rng: np.random.Generator) -> bytes:
    frames = _ubx_frames(data)
    start, size = frames[int(rng.integers(len(frames)))]
    frame = bytearray(data[start : start + size])
    how = int(rng.integers(5))
    if how == 0 and size > 8:  # a payload byte flipped, the checksum made good
        frame[6 + int(rng.integers(size - 8))] ^= 1 << int(rng.integers(8))
        frame[-2:] = checksum(bytes(frame[2:-2]))
    elif how == 1:  # the length edited (the checksum made good over what is there)
        n = int(rng.choice([0, 1, 0xFFFF, size - 9, size + 7]))
        frame[4:6] = (max(n, 0) & 0xFFFF).to_bytes(2, "little")
        frame[-2:] = checksum(bytes(frame[2:-2]))
    elif how == 2:  # the frame twice
        frame = frame + frame
    elif how == 3:  # NUL run
        frame = frame[: size // 2] + bytes(int(rng.integers(1, 5000))) + frame[size // 2 :]
    else:  # the log cut inside the frame
        return data[: start + int(rng.integers(size))]
    return data[:start] + bytes(frame) + data[start + size :]


def _mutate_text(data: bytes, rng: np.random.Generator) -> bytes:
    lines = data.split(b"\n")
    k = int(rng.integers(len(lines)))
    how = int(rng.integers(8))
    if how == 0:  # a bit flipped anywhere
        b = bytearray(data)
        b[int(rng.integers(len(b)))] ^= 1 << int(rng.integers(8))
        return bytes(b)
    if how == 1:  # cut
        return data[: int(rng.integers(len(data)))]
    if how == 2:  # a line twice
        lines.insert(k, lines[k])
    elif how == 3:  # two lines swapped
        j = int(rng.integers(len(lines)))
        lines[k], lines[j] = lines[j], lines[k]
    elif how in (4, 5, 6):  # numbers replaced by odd ones (several in one line)
        numbers = list(_NUMBER.finditer(lines[k]))
        for m in sorted((numbers[int(i)] for i in rng.integers(len(numbers), size=min(3, len(numbers)))) if numbers else (),
                        key=lambda m: -m.start()):  # fmt: skip
            lines[k] = lines[k][: m.start()] + ODD_NUMBERS[int(rng.integers(len(ODD_NUMBERS)))] + lines[k][m.end() :]
    else:  # a NUL run or a 300 kB field
        filler = bytes(int(rng.integers(1, 5000))) if rng.integers(2) else b"7" * 300_000
        cut = int(rng.integers(len(lines[k]) + 1))
        lines[k] = lines[k][:cut] + filler + lines[k][cut:]
    return b"\n".join(lines)


#: cases a long run found failing once (every run replays them): a damaged receiver clock left a record without a
#: time (KeyError 'tod_s'; a merge on a null time), a date in the year 0 (strftime), a satellite number of 14 000 000
FOUND = (("device-gnss", 134), ("gnsslogger", 25), ("gnsslogger", 49), ("rtklib-pos", 32), ("rtklib-pos", 141), ("librsf", 146),
         ("osnma-vector", 139), ("osnma-key", 41),  # (and an OSNMA vector that authenticated nothing, a key file not UTF-8,
         ("roads-dbf", 19), ("roads-geojson", 10))  # a .dbf naming two columns alike, a road coordinate of 400 digits)


def _cases() -> list[tuple[str, int]]:
    kinds = [k for k in SEEDS if (SHARED / SEEDS[k][0]).exists()] + list(WRITTEN) + list(ROADS)
    per_kind = max(EXAMPLES // (len(SEEDS) + len(WRITTEN) + len(ROADS)), 2)
    cases = [(kind, i) for kind in kinds for i in range(per_kind)]
    return cases + [c for c in FOUND if c not in cases and c[0] in kinds]


@pytest.mark.parametrize("kind,case", _cases(), ids=[f"{k}-{i}" for k, i in _cases()])
def test_a_mutated_real_file_gets_a_documented_exit(tmp_path, kind, case):
    rng = np.random.default_rng([case, sum(kind.encode())])
    data = _seed(kind)
    for _ in range(int(rng.integers(1, 4))):  # one to three mutations
        data = (_mutate_ubx if kind.startswith("ubx") else _mutate_text)(data, rng)
    if kind in WRITTEN:
        runs = _written_runs(tmp_path, kind, data)
    elif kind in ROADS:
        files = dict(_road_files())
        files[_road_target(kind)] = data
        for name, content in files.items():
            (tmp_path / name).write_bytes(content)
        main = "roads.shp" if kind in ("roads-shp", "roads-dbf", "roads-prj") else _road_target(kind)
        out = tmp_path / "geo.geojson"
        runs = ((("geoobjects", "build", str(tmp_path / main), "-q", "-o", str(out)), out),)
    elif kind in OSNMA_KINDS:
        log = tmp_path / os.path.basename(SEEDS[kind][0])  # (a test vector's name gives its start time)
        log.write_bytes(data)
        out = tmp_path / "o.csv"
        runs = ((("osnma", str(log), *SEEDS[kind][2], "-q", "-o", str(out)), out),)
    else:
        log = tmp_path / os.path.basename(SEEDS[kind][0])
        log.write_bytes(data)
        out = tmp_path / "e.csv"
        fmt = ("--input-format", kind) if kind in ("librsf", "rinex", "gnsslogger", "device-gnss", "gsdc-derived", "gpsd-json") else ()
        runs = ((("info", str(log)), None), (("integrity", str(log), *fmt, *SEEDS[kind][2], "-q", "-o", str(out)), out))
    for args, output in runs:
        code, err = run_main(*args)
        assert code in DOCUMENTED and "Traceback" not in err and "internal error" not in err, f"{kind}-{case} {args[0]}: exit {code}: {err}"
        if code in (1, 2):
            assert err.strip().splitlines()[-1].startswith("tollcli: error"), err
            assert len(err.strip().splitlines()) == 1, err
            if output is not None:
                assert not output.exists(), f"{kind}-{case}: exit {code} left {output}"


def _written_runs(tmp_path, kind: str, data: bytes):
    """The commands that read a mutated invoice (``info``, ``verify``, ``--config``), settings file (``--config``),
    truth trajectory (``audit --truth``) or fleet file (``batch --fleet``)."""
    path = tmp_path / {"invoice": "invoice.json", "settings": "settings.toml", "truth": "truth.csv", "fleet": "fleet.csv",
                       "roadside": "reads.csv", "osnma-key": "OSNMA_PublicKey_1.xml"}[kind]  # fmt: skip
    path.write_bytes(data)
    out = tmp_path / "c.json"
    drive = str(REPO / "samples" / "straight-drive.nmea")
    if kind == "truth":
        invoice = tmp_path / "invoice.json"
        _written_seed("invoice")
        invoice.write_bytes(_WRITTEN_SEEDS["rural invoice"])
        return ((("audit", str(invoice), "--truth", str(path), "--geo", GEO, "-q", "-o", str(out)), out),)
    if kind == "roadside":
        gantries = tmp_path / "gantries.geojson"
        gantries.write_text(json.dumps({"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {"id": "G1"}, "geometry": {"type": "Point", "coordinates": [2.8955, 42.6990]}},
            {"type": "Feature", "properties": {"id": "G2"}, "geometry": {"type": "Point", "coordinates": [2.8960, 42.7100]}}]}))  # fmt: skip
        return ((("enforce", drive, "--reads", str(path), "--gantries", str(gantries), "--tag", "TAG-1", "-q", "-o", str(out)), out),)
    if kind == "osnma-key":
        ublox = SHARED / "osnma" / "ublox"
        return ((("osnma", str(ublox / "current_config.ubx"), "--merkle", str(ublox / "OSNMA_MerkleTree.xml"), "--public-key", str(path),
                  "-q", "-o", str(tmp_path / "o.csv")), tmp_path / "o.csv"),)  # fmt: skip
    if kind == "fleet":
        return ((("batch", drive, "--fleet", str(path), "--geo", GEO, "--tariff", TARIFF, "--workers", "1", "-q",
                  "-o", str(tmp_path / "out")), None),)  # fmt: skip
    process = (("process", drive, "--config", str(path), "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(out)), out)
    if kind == "settings":
        return (process,)
    return (("info", str(path)), None), (("verify", str(path)), None), process
