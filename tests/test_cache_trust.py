"""Nothing on disk but the inputs decides a charge: the cache's stores and tables are verified, owned, and never
the reason an invoice differs; settings files cannot redirect what a run reads or writes."""

from __future__ import annotations

import hashlib
import io
import json
import multiprocessing
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, SAMPLES, run_main

from tollcli import cache
from tollcli.charging.invoice import content_sha256
from tollcli.geoobjects import store as geoobject_store
from tollcli.geoobjects.store_files import MANIFEST, STRINGS, VERIFIED, manifest_sha256

LOG = str(SAMPLES / "straight-drive.nmea")
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def _process(out: Path, *extra: str) -> tuple[int, str]:
    return run_main("process", LOG, "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "-q", *extra)


@pytest.fixture()
def charged(tmp_path, monkeypatch):
    """A cache with the example network's store, and the invoice charged without any cache."""
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    truth = tmp_path / "truth.json"
    assert _process(truth)[0] == 0
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    first = tmp_path / "first.json"
    assert _process(first)[0] == 0
    assert first.read_bytes() == truth.read_bytes()  # a cold cache changes nothing, the store digest included
    store = next((tmp_path / "cache" / "geoobjects").glob(f"*.v{geoobject_store.STORE_FORMAT}"))
    return tmp_path, truth.read_bytes(), store


def _alterations(path: Path, files: list[Path]) -> list[tuple[str, object]]:
    """(name, how) pairs: each changes one file of a store in a way a manifest check must catch."""
    out: list[tuple[str, object]] = [("truncated", lambda: path.write_bytes(path.read_bytes()[: max(1, path.stat().st_size // 2)])),
                                     ("one byte", lambda: _flip_last_byte(path)), ("removed", lambda: path.unlink())]  # fmt: skip
    other = next((f for f in files if f != path and f.suffix == path.suffix), None)
    if other is not None:
        out.append((f"swapped with {other.name}", lambda: _swap(path, other)))
    if path.suffix == ".npy":
        value = np.load(path)
        if value.dtype.kind == "f" and value.size:
            for name, x in (("value edit", 5.0), ("NaN", np.nan), ("inf", np.inf), ("scaled", None)):
                out.append((name, lambda x=x: _save_edited(path, x)))
        if len(value) > 1:
            out.append(("reordered", lambda: np.save(path, value[::-1].copy())))
        if value.dtype.kind in "iu" and value.size:
            out.append(("zeroed", lambda: np.save(path, np.zeros_like(value))))
    if path.suffix == ".npy" or path.name == STRINGS:  # the same size, the modification time set back: ctime tells
        out.append(("edited in place, mtime restored", lambda: _edit_keeping_mtime(path)))
    if path.name == VERIFIED:
        out.append(("stale", lambda: path.write_text(json.dumps([]))))
    elif path.suffix != ".npy":
        doc = json.loads(path.read_text())
        if path.name == STRINGS:
            out.append(("ids reversed", lambda: path.write_text(json.dumps({**doc, "ids": doc["ids"][::-1]}))))
        else:
            out.append(("a digest changed", lambda: path.write_text(json.dumps({**doc, "source_sha256": "0" * 64}))))
    return out


def _edit_keeping_mtime(path: Path) -> None:
    st = path.stat()
    data = bytearray(path.read_bytes())
    data[-1] ^= 0x01
    with open(path, "r+b") as fh:
        fh.write(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))


def _flip_last_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[-1] ^= 0x01
    path.write_bytes(bytes(data))


def _swap(a: Path, b: Path) -> None:
    tmp = a.with_suffix(".swap")
    os.replace(a, tmp)
    os.replace(b, a)
    os.replace(tmp, b)


def _save_edited(path: Path, x) -> None:
    value = np.load(path).copy()
    if x is None:
        value *= 100.0
    else:
        value.flat[0] = x
    np.save(path, value)


def test_every_altered_store_file_is_compiled_again_or_refused(charged):
    """The tamper matrix: every file of a compiled store, altered every way; ``process`` writes the true invoice (the
    store compiled again) or fails in one line — never a different invoice with exit 0."""
    tmp_path, truth, store = charged
    files = sorted(store.iterdir())
    assert {f.name for f in files} >= {MANIFEST, STRINGS, "hal_m.npy", "length_m.npy", "grid_members.npy", "bounds.npy"}
    pristine = tmp_path / "pristine"
    shutil.copytree(store, pristine)
    tried = 0
    for file in files:
        for name, alter in _alterations(store / file.name, [store / f.name for f in files]):
            shutil.rmtree(store)
            shutil.copytree(pristine, store)
            before = {f.name: f.read_bytes() for f in store.iterdir()}
            alter()
            if {f.name: f.read_bytes() for f in store.iterdir()} == before:
                continue  # (reordering a column of equal values changes nothing)
            warnings.onceregistry.clear()  # (the note is said once per message and process: this test is one process)
            out = tmp_path / "out.json"
            out.unlink(missing_ok=True)
            code, err = _process(out)
            tried += 1
            if code == 0:
                assert out.read_bytes() == truth, f"{file.name} {name}: a different invoice with exit 0"
                assert "compiled again" in err or file.name == VERIFIED, (file.name, name)
            else:
                assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, (file.name, name, err)
            if code == 0:  # compiled again: the store is whole again, byte for byte (its check record aside)
                whole = {f.name: f.read_bytes() for f in store.iterdir() if f.name != VERIFIED}
                assert whole == {f.name: f.read_bytes() for f in pristine.iterdir() if f.name != VERIFIED}, (file.name, name)
                continue
            again = tmp_path / "again.json"  # refused: the next run compiles the store again and charges the truth
            assert _process(again)[0] == 0 and again.read_bytes() == truth, (file.name, name)
    assert tried >= 80


def test_a_store_checked_once_is_not_hashed_again_until_a_file_changes(charged, monkeypatch):
    tmp_path, truth, store = charged
    from tollcli.geoobjects import store_files

    hashed = []
    monkeypatch.setattr(store_files, "array_digest", lambda v: hashed.append(1) or cache.array_digest(v))
    geoobject_store.load_geoobjects(GEO)
    assert not hashed  # the files are as they were checked
    os.utime(store / "hal_m.npy")  # touched: hashed again, and found intact
    geoobject_store.load_geoobjects(GEO)
    assert hashed


def _forge(store: Path, name: str, edit) -> None:
    """An attacker who rewrites the manifest too: the store verifies, with changed values."""
    path = store / name
    value = np.load(path).copy()
    edit(value)
    np.save(path, value)
    manifest = json.loads((store / MANIFEST).read_text())
    manifest["files"][name] = cache.array_digest(np.load(path))
    (store / MANIFEST).write_text(json.dumps(manifest, sort_keys=True))


def test_verify_recomputes_without_the_cache(charged, monkeypatch):
    """A store forged consistently (manifest rewritten) changes ``process``'s invoice — it records the store it was
    charged with — and ``verify`` exits 1 naming the difference; ``verify --use-cache`` reproduces it and says so."""
    tmp_path, truth, store = charged
    _forge(store, "hal_m.npy", lambda v: v.__setitem__(0, 5.0))
    forged = tmp_path / "forged.json"
    assert _process(forged)[0] == 0
    doc = json.loads(forged.read_bytes())
    assert forged.read_bytes() != truth
    assert doc["inputs"]["geoobjects_store_sha256"] != json.loads(truth)["inputs"]["geoobjects_store_sha256"]
    code, err = run_main("verify", str(forged))
    assert code == 1 and "different invoice" in err and "geoobjects_store_sha256" in err and "total" in err, err
    code, err = run_main("verify", str(forged), "--use-cache", "--json")
    assert code == 0, err
    honest = tmp_path / "honest.json"
    honest.write_bytes(truth)
    code, err = run_main("verify", str(honest))
    assert code == 0 and "cache not used" in err, err


def _forge_row(path: Path, edit) -> None:
    """A stored table rewritten with its digest: a consistent forgery."""
    _, _, body = path.read_bytes().partition(b"\n")
    forged = io.BytesIO()
    np.save(forged, edit(np.load(io.BytesIO(body))))
    path.write_bytes(b"tollcli-cache-1 " + hashlib.sha256(forged.getvalue()).hexdigest().encode() + b"\n" + forged.getvalue())


def test_threshold_and_sigma_tables_are_checked(tmp_path):
    """A stored threshold or σ table altered without its digest is computed again; ETC thresholds forged to 1e12
    with their digest change the run, and ``verify`` (no cache) says the invoice is not reproduced."""
    env = {**os.environ, "TOLLCLI_CACHE_DIR": str(tmp_path / "cache")}
    urban = str(SAMPLES / "sim" / "urban-fault" / "drive.nmea")

    def charge(out: Path) -> bytes:
        r = subprocess.run([sys.executable, "-m", "tollcli", "process", urban, "--geo", GEO, "--tariff", TARIFF, "--raim", "etc",
                            "-q", "-o", str(out)], capture_output=True, cwd=REPO, env=env, timeout=300)  # fmt: skip
        assert r.returncode == 0, r.stderr
        return out.read_bytes()

    truth = charge(tmp_path / "a.json")
    rows = sorted((tmp_path / "cache" / "thresholds").iterdir()) + sorted((tmp_path / "cache" / "sigma").iterdir())
    assert len(rows) >= 10
    for row in rows:  # an edit without its digest: recomputed (and rewritten)
        row.write_bytes(row.read_bytes()[:-8] + np.float64(1e12).tobytes())
    assert charge(tmp_path / "b.json") == truth
    for row in rows:
        if row.name.startswith("etc-threshold"):
            _forge_row(row, lambda v: np.full_like(v, 1e12))
    assert charge(tmp_path / "c.json") != truth  # the forged cache decided statuses
    r = subprocess.run([sys.executable, "-m", "tollcli", "verify", str(tmp_path / "c.json")], capture_output=True, cwd=REPO,
                       env=env, timeout=300)  # fmt: skip
    assert r.returncode == 1 and b"different invoice" in r.stderr and len(r.stderr.splitlines()) == 1, r.stderr
    (tmp_path / "a2.json").write_bytes(truth)
    r = subprocess.run([sys.executable, "-m", "tollcli", "verify", str(tmp_path / "a2.json")], capture_output=True, cwd=REPO, env=env)
    assert r.returncode == 0, r.stderr


# ---------------------------------------------------------------- who may write the cache
def test_a_cache_others_can_write_is_not_used(tmp_path, monkeypatch):
    open_dir = tmp_path / "open"
    open_dir.mkdir()
    open_dir.chmod(0o777)  # writable by all, no sticky bit: anyone could replace a store
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(open_dir))
    with pytest.warns(cache.CacheNotUsed, match="writable by other users"):
        assert cache.cache_dir() is None
    out = tmp_path / "o.json"
    code, err = _process(out)
    assert code == 0 and not any(open_dir.iterdir())
    group = tmp_path / "group"
    group.mkdir()
    group.chmod(0o770)
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(group))
    with pytest.warns(cache.CacheNotUsed):
        assert cache.cache_dir() is None


def test_a_shared_sticky_cache_holds_a_private_folder_per_user(tmp_path, monkeypatch):
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o1777)
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(shared))
    mine = cache.cache_dir()
    assert mine == shared / f"tollcli-{os.getuid()}" and stat.S_IMODE(mine.stat().st_mode) == 0o700
    # somebody else made "my" folder first (here: a folder others can write): not used, the run goes on
    shutil.rmtree(mine)
    mine.mkdir()
    mine.chmod(0o777)
    with pytest.warns(cache.CacheNotUsed, match="only you can write"):
        assert cache.cache_dir() is None
    out = tmp_path / "o.json"
    assert _process(out)[0] == 0 and not any(mine.iterdir())


def _owned_by_another(path: Path, monkeypatch) -> None:
    """Make ``path`` (recursively) another user's: chown as root, else run as if this process were another user."""
    if os.geteuid() == 0:
        for p in [path, *path.rglob("*")]:
            os.lchown(p, 4242, 4242)
    else:
        monkeypatch.setattr(cache.os, "getuid", lambda: 4242)


def test_a_cache_or_store_of_another_owner_is_not_used(charged, monkeypatch):
    tmp_path, truth, store = charged
    _owned_by_another(store, monkeypatch)
    out = tmp_path / "o.json"
    warnings.onceregistry.clear()
    code, err = _process(out)
    assert code == 0 and out.read_bytes() == truth and "not used" in err, err
    _owned_by_another(tmp_path / "cache", monkeypatch)
    with pytest.warns(cache.CacheNotUsed, match="not yours"):
        assert cache.cache_dir() is None


def _as_user(uid: int, *args: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(["setpriv", f"--reuid={uid}", f"--regid={uid}", "--clear-groups", sys.executable, "-m", "tollcli", *args],
                          capture_output=True, cwd="/", env={**os.environ, **env, "HOME": "/nonexistent"}, timeout=300)  # fmt: skip


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("setpriv") is None, reason="needs root and setpriv to act as two users")
def test_two_users_share_a_sticky_cache_safely(tmp_path):
    """Two users on one ``chmod 1777`` cache: each charges with a private store; neither can change the other's
    invoices (the other's folder cannot be written), neither is locked out."""
    import tempfile

    base = Path(tempfile.mkdtemp(prefix="tollcli-shared-"))
    try:
        base.chmod(0o755)
        shared = base / "cache"
        shared.mkdir()
        shared.chmod(0o1777)
        inputs = base / "in"
        inputs.mkdir()
        for f in (LOG, GEO, TARIFF):
            shutil.copy(f, inputs)
        env = {"TOLLCLI_CACHE_DIR": str(shared)}
        outs = {}
        for uid in (61001, 61002):
            out = base / f"out-{uid}"
            out.mkdir()
            os.chown(out, uid, uid)
            r = _as_user(uid, "process", str(inputs / Path(LOG).name), "--geo", str(inputs / Path(GEO).name), "--tariff",
                         str(inputs / Path(TARIFF).name), "-q", "-o", str(out / "i.json"), env=env)  # fmt: skip
            if r.returncode != 0 and b"Permission denied" in r.stderr and b"python" in r.stderr.lower():
                pytest.skip("the interpreter is not readable by another user here")
            assert r.returncode == 0, r.stderr
            outs[uid] = (out / "i.json").read_bytes()
            folder = shared / f"tollcli-{uid}"
            assert folder.stat().st_uid == uid and stat.S_IMODE(folder.stat().st_mode) == 0o700
        assert outs[61001] == outs[61002]
        # the second user tries to reach into the first one's store: refused by the system
        r = subprocess.run(["setpriv", "--reuid=61002", "--regid=61002", "--clear-groups", "touch",
                            str(shared / "tollcli-61001" / "geoobjects" / "x")], capture_output=True)  # fmt: skip
        assert r.returncode != 0
        # a third user squats the folder of a user who has not run yet: that user is told, charged right, not locked out
        squat = shared / "tollcli-61003"
        subprocess.run(["setpriv", "--reuid=61002", "--regid=61002", "--clear-groups", "mkdir", "-m", "777", str(squat)], check=True)
        out = base / "out-61003"
        out.mkdir()
        os.chown(out, 61003, 61003)
        r = _as_user(61003, "process", str(inputs / Path(LOG).name), "--geo", str(inputs / Path(GEO).name), "--tariff",
                     str(inputs / Path(TARIFF).name), "-o", str(out / "i.json"), env=env)  # fmt: skip
        assert r.returncode == 0 and b"not used" in r.stderr, r.stderr
        assert (out / "i.json").read_bytes() == outs[61001]
        assert not any(squat.iterdir())
    finally:
        shutil.rmtree(base, ignore_errors=True)


# ---------------------------------------------------------------- writers that run at once
def _network(path: Path, n: int) -> str:
    """A GeoJSON of ``n`` small square geo-objects near Helsinki (big enough that compiles overlap)."""
    features = []
    for i in range(n):
        lon, lat = 24.9 + (i % 100) * 0.002, 60.1 + (i // 100) * 0.002
        ring = [[lon, lat], [lon + 0.001, lat], [lon + 0.001, lat + 0.0005], [lon, lat + 0.0005], [lon, lat]]
        features.append({"type": "Feature", "properties": {"id": f"g{i}", "hal_m": 20, "road_class": "motorway"},
                         "geometry": {"type": "Polygon", "coordinates": [ring]}})  # fmt: skip
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return str(path)


def _load(args) -> str:
    cache_dir, geo, start = args
    os.environ["TOLLCLI_CACHE_DIR"] = cache_dir
    while time.time() < start:
        time.sleep(0.001)
    geo_objects = geoobject_store.load_geoobjects(geo)
    return geo_objects.store_sha256


def test_concurrent_cold_compiles_never_fail(tmp_path):
    """6 processes compile one new store at once, 10 rounds (a damaged store in place in every other round): none
    fails, all charge with the same store, no temporary folder is left."""
    geo = _network(tmp_path / "net.geojson", 1500)
    expected = None
    # forkserver, not fork: a child forked from a test worker that other tests left with threads (pyarrow's pool,
    # BLAS) can block forever on a lock one of them held at the fork (seen once: one child of six, the map waiting)
    ctx = multiprocessing.get_context("forkserver")
    with ctx.Pool(6) as pool:
        for round_ in range(10):
            cache_dir = tmp_path / f"cache{round_}"
            if round_ % 2:  # a damaged store already there: set aside by one writer, never by two
                cache_dir.mkdir(mode=0o700)
                os.environ["TOLLCLI_CACHE_DIR"] = str(cache_dir)
                geoobject_store.load_geoobjects(geo)
                store = next((cache_dir / "geoobjects").glob("*.v*"))
                (store / "hal_m.npy").write_bytes(b"damaged")
            start = time.time() + 0.3
            digests = pool.map(_load, [(str(cache_dir), geo, start)] * 6)
            expected = expected or digests[0]
            assert digests == [expected] * 6
            left = [p.name for p in (cache_dir / "geoobjects").iterdir() if p.suffix in (".tmp", ".old")]
            assert not left, left
    os.environ.pop("TOLLCLI_CACHE_DIR", None)


def test_concurrent_commands_on_a_cold_cache_agree(tmp_path):
    """Three ``process`` and three ``geoobjects compile`` started together on a cold cache: all succeed, the three
    invoices are byte-identical to one charged without a cache."""
    geo = _network(tmp_path / "net.geojson", 3000)
    env = {**os.environ, "TOLLCLI_CACHE_DIR": str(tmp_path / "cache")}
    charge = [sys.executable, "-m", "tollcli", "process", LOG, "--geo", geo, "--tariff", TARIFF, "-q", "-o"]
    procs = [subprocess.Popen([*charge, str(tmp_path / f"i{k}.json")] if k % 2 == 0 else
                              [sys.executable, "-m", "tollcli", "geoobjects", "compile", geo, "-q"],
                              env=env, cwd=REPO, stderr=subprocess.PIPE) for k in range(6)]  # fmt: skip
    errors = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    assert all(code == 0 for code, _ in errors), errors
    r = subprocess.run([*charge, str(tmp_path / "off.json")], env={**env, "TOLLCLI_CACHE_DIR": "off"}, cwd=REPO, capture_output=True)
    assert r.returncode == 0, r.stderr
    assert {(tmp_path / f"i{k}.json").read_bytes() for k in (0, 2, 4)} == {(tmp_path / "off.json").read_bytes()}
    assert not [p.name for p in (tmp_path / "cache" / "geoobjects").iterdir() if p.suffix in (".tmp", ".old")]


def test_a_compile_killed_anywhere_leaves_nothing_behind(tmp_path):
    """``kill -9`` at random points of ``geoobjects compile``; the next compile removes what the dead one left, and the
    invoice is byte-identical to one charged without a cache."""
    geo = _network(tmp_path / "net.geojson", 6000)
    env = {**os.environ, "TOLLCLI_CACHE_DIR": str(tmp_path / "cache")}
    rng = np.random.default_rng(9)
    for delay in rng.uniform(0.3, 2.5, 5):
        proc = subprocess.Popen([sys.executable, "-m", "tollcli", "geoobjects", "compile", geo, "-q"], env=env, cwd=REPO,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        store = tmp_path / "cache" / "geoobjects"
        if store.is_dir():
            for done in store.glob("*.v*"):
                shutil.rmtree(done)  # compiled before the kill: start cold again
    r = subprocess.run([sys.executable, "-m", "tollcli", "geoobjects", "compile", geo, "-q"], env=env, cwd=REPO, capture_output=True)
    assert r.returncode == 0, r.stderr
    assert not [p.name for p in (tmp_path / "cache" / "geoobjects").iterdir() if p.suffix in (".tmp", ".old")]
    off = tmp_path / "off.json"
    on = tmp_path / "on.json"
    for out, cache_env in ((off, "off"), (on, str(tmp_path / "cache"))):
        r = subprocess.run([sys.executable, "-m", "tollcli", "process", LOG, "--geo", geo, "--tariff", TARIFF, "-q", "-o", str(out)],
                           env={**os.environ, "TOLLCLI_CACHE_DIR": cache_env}, cwd=REPO, capture_output=True)  # fmt: skip
        assert r.returncode == 0, r.stderr
    assert off.read_bytes() == on.read_bytes()


# ---------------------------------------------------------------- settings files
@pytest.mark.parametrize("key,value", [("output", "victim.json"), ("format", "csv"), ("geo", "other.geojson"), ("tariff", "t.toml"),
                                       ("nav", "brdc.nav"), ("roads", "r.geojson"), ("workers", 8), ("osnma_merkle", "m.xml")])  # fmt: skip
def test_a_settings_file_cannot_name_files_or_outputs(tmp_path, monkeypatch, key, value):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    victim = tmp_path / "victim.json"
    victim.write_text("precious\n")
    for name, text in (("hostile.json", json.dumps({"parameters": {key: value}})), ("hostile.toml", f"{key} = {json.dumps(value)}\n")):
        (tmp_path / name).write_text(text)
        out = tmp_path / "mine.json"
        code, err = _process(out, "--config", str(tmp_path / name))
        assert code == 2 and f"{key!r} is not a setting" in err and len(err.strip().splitlines()) == 1, err
        assert victim.read_text() == "precious\n" and not out.exists()


@pytest.mark.parametrize("key,value,word", [("date", 12, "date"), ("date", "9999-99-99", "date"), ("strict", "yes", "true or false"),
                                            ("fde", 1, "true or false"), ("tc", "5", "number"), ("n_th", 2.5, "whole number"),
                                            ("raim", 3, "text")])  # fmt: skip
def test_settings_values_are_typed(tmp_path, monkeypatch, key, value, word):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    (tmp_path / "s.json").write_text(json.dumps({"parameters": {key: value}}))
    code, err = _process(tmp_path / "o.json", "--config", str(tmp_path / "s.json"))
    assert code == 2 and word in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert not (tmp_path / "o.json").exists()


@pytest.mark.parametrize("key,value", [("date", "9999-99-99"), ("date", 12), ("strict", "yes"), ("fde", "no"), ("vehicle", 7)])
def test_verify_types_an_invoices_parameters(tmp_path, monkeypatch, key, value):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    inv = tmp_path / "i.json"
    assert _process(inv)[0] == 0
    doc = json.loads(inv.read_text())
    doc["parameters"][key] = value
    doc["content_sha256"] = content_sha256(doc)
    inv.write_text(json.dumps(doc))
    code, err = run_main("verify", str(inv))
    assert code == 2 and key in err and len(err.strip().splitlines()) == 1 and "internal error" not in err, err


def test_verify_says_nothing_of_files_that_are_not_the_inputs(tmp_path, monkeypatch):
    """An untrusted invoice may name any path: verify reports no digest and nothing read from a file that is not
    the recorded input."""
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    inv = tmp_path / "i.json"
    assert _process(inv)[0] == 0
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x:0:0\n" * 30)
    actual = hashlib.sha256(secret.read_bytes()).hexdigest()
    for key in ("log", "geoobjects", "tariff"):
        doc = json.loads(inv.read_text())
        doc["inputs"][key] = str(secret)
        doc["content_sha256"] = content_sha256(doc)
        probe = tmp_path / f"probe-{key}.json"
        probe.write_text(json.dumps(doc))
        code, err = run_main("verify", str(probe))
        said = err.replace(str(tmp_path), "")
        assert code == 1 and actual[:8] not in said and "30" not in said and "root" not in said and "line" not in said, err


def test_the_store_digest_is_the_same_compiled_anywhere(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    in_memory = geoobject_store.load_geoobjects(GEO)
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "c"))
    on_disk = geoobject_store.load_geoobjects(GEO)
    mapped = geoobject_store.load_geoobjects(GEO)
    assert in_memory.store is None and on_disk.store is not None and mapped.store == on_disk.store
    manifest = json.loads((on_disk.store / MANIFEST).read_text())
    assert in_memory.store_sha256 == on_disk.store_sha256 == mapped.store_sha256 == manifest_sha256(manifest)
