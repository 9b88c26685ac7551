"""``process`` hashes the geo-object file on a thread of its own while it opens the log and reads its first chunks
(``tollcli/job/pipeline.py``: ``_GeoObjectsAhead``): the same invoice as with the digest given (as a batch gives it),
and where the log and the geo-objects (or the tariff against them) are both wrong, the same one-line error as when
the geo-objects were loaded before the log was opened: theirs.
"""

from __future__ import annotations

import pytest
from conftest import REPO, SAMPLES, run_main

from tollcli.charging.invoice import invoice_json
from tollcli.io.sources import file_sha256
from tollcli.job.pipeline import ChargeSettings, charge_log

GEO = REPO / "geoobjects" / "example-geoobjects.geojson"
TARIFF = REPO / "geoobjects" / "example-tariff.toml"
LOG = SAMPLES / "straight-drive.nmea"


@pytest.mark.parametrize("sample", ["straight-drive.nmea", "sim/urban-fault/drive.nmea"])
def test_the_invoice_is_the_same_whether_the_digest_is_given_or_made_beside_the_reading(sample):
    log = str(SAMPLES / sample)
    made = invoice_json(charge_log(log, str(GEO), str(TARIFF), ChargeSettings())[0])
    given = invoice_json(charge_log(log, str(GEO), str(TARIFF), ChargeSettings(), geo_sha256=file_sha256(str(GEO)))[0])
    assert made == given and '"lines"' in made


def _log(tmp_path, problem: str) -> str:
    if problem == "missing":
        return str(tmp_path / "no-such.nmea")
    if problem == "not a log":
        path = tmp_path / "binary.nmea"
        path.write_bytes(bytes(range(256)) * 64)
        return str(path)
    return str(LOG)


def _geo_and_tariff(tmp_path, problem: str) -> tuple[str, str]:
    if problem == "missing":
        return str(tmp_path / "no-such.geojson"), str(TARIFF)
    if problem == "not GeoJSON":
        path = tmp_path / "broken.geojson"
        path.write_text('{"type": "FeatureCollection", "features": [')
        return str(path), str(TARIFF)
    tariff = tmp_path / "tariff.toml"  # a tariff naming a geo-object the file does not have
    tariff.write_text(TARIFF.read_text() + '\n[length_km]\n"NO-SUCH-SECTION" = 1.5\n')
    return str(GEO), str(tariff)


@pytest.mark.parametrize("geo_problem", ["missing", "not GeoJSON", "the tariff names an unknown geo-object"])
@pytest.mark.parametrize("log_problem", ["missing", "not a log"])
def test_the_geo_objects_error_comes_first_whatever_is_wrong_with_the_log(tmp_path, log_problem, geo_problem):
    geo, tariff = _geo_and_tariff(tmp_path, geo_problem)
    out = tmp_path / "invoice.json"
    alone = run_main("process", str(LOG), "--geo", geo, "--tariff", tariff, "-o", str(out))  # the log sound
    both = run_main("process", _log(tmp_path, log_problem), "--geo", geo, "--tariff", tariff, "-o", str(out))
    assert alone[0] != 0 and both == alone
    assert len(both[1].strip().splitlines()) == 1 and "Traceback" not in both[1]
    assert not out.exists()


@pytest.mark.parametrize("log_problem", ["missing", "not a log"])
def test_a_wrong_log_with_sound_geo_objects_is_its_own_error(tmp_path, log_problem):
    log = _log(tmp_path, log_problem)
    code, err = run_main("process", log, "--geo", str(GEO), "--tariff", str(TARIFF), "-o", str(tmp_path / "i.json"))
    assert code != 0 and log in err and len(err.strip().splitlines()) == 1
