"""Findings at the rates receivers log at: a fault-free drive accuses nobody at 1, 2, 5, 10 or 20 Hz in any street
environment, and a Doppler speed that disagrees with the fixes is still found at every rate.

Before: the Doppler check took the path length of noisy 0.1 s steps for the vehicle's speed (186 false spoofing
findings at 10 Hz), and the RAIM-alarm check counted 30 epochs — 1.5 s at 20 Hz — as independent trials."""

from __future__ import annotations

import json

import pytest
from conftest import REPO, run_cli

from tollcli.readers.nmea.compose import with_checksum

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
ROADS = str(REPO / "geoobjects" / "example-roads.geojson")
RATES = (1, 2, 5, 10, 20)
_drives: dict = {}


def _drive(tmp_path_factory, env: str, rate: int):
    if (env, rate) not in _drives:
        out = tmp_path_factory.mktemp(f"{env}-{rate}hz")
        r = run_cli("simulate", "--route", ROADS, "--via", "A9-N1", "--geo", GEO, "--env", env, "--seed", "1", "--rate", str(rate),
                    "-o", str(out), "-q")  # fmt: skip
        assert r.returncode == 0, r.stderr
        _drives[env, rate] = out / "drive.nmea"
    return _drives[env, rate]


def _findings(log) -> list[dict]:
    r = run_cli("findings", str(log), "-o", "-", "-q")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)["findings"]


@pytest.mark.parametrize("rate", RATES)
@pytest.mark.parametrize("env", ["urban", "rural", "open"])
def test_a_fault_free_drive_accuses_nobody_at_any_rate(tmp_path_factory, env, rate):
    found = [(f["kind"], f["start_utc"]) for f in _findings(_drive(tmp_path_factory, env, rate)) if f["category"] in ("spoofing", "jamming")]
    assert found == []


def _slow_rmc(log, out, t0: str, t1: str) -> None:
    """Every RMC with its time in [t0, t1] (hhmmss) reports half the speed: 7 m/s on a 14 m/s drive."""
    lines = []
    for line in log.read_text().splitlines():
        fields = line[1 : line.index("*")].split(",") if "*" in line else []
        if fields and fields[0].endswith("RMC") and t0 <= fields[1][:6] <= t1 and fields[7]:
            fields[7] = f"{float(fields[7]) / 2:.3f}"
            line = with_checksum(",".join(fields))
        lines.append(line)
    out.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("rate", RATES)
def test_a_doppler_speed_that_disagrees_with_the_fixes_is_found_at_every_rate(tmp_path_factory, tmp_path, rate):
    log = tmp_path / "slow.nmea"
    _slow_rmc(_drive(tmp_path_factory, "rural", rate), log, "080020", "080059")
    found = [f for f in _findings(log) if f["kind"] == "doppler_mismatch"]
    assert len(found) == 1 and found[0]["category"] == "spoofing"
    evidence = found[0]["evidence"]
    assert evidence["position_speed_mps"] == pytest.approx(2 * evidence["reported_speed_mps"], rel=0.15)
    assert "08:00:2" in found[0]["start_utc"] or "08:00:3" in found[0]["start_utc"]
