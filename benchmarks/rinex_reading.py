"""Reading a RINEX observation file (2 or 3): tollcli's direct reader against georinex (what it read through before),
on the same file in the same run, and whether the two give the same rows.

    python benchmarks/rinex_reading.py [--epochs 3600] [--file OBS ...]

Default: synthetic files of ``--epochs`` epochs at 1 Hz, GPS and Galileo, in RINEX 3.04 and in RINEX 2.11
(``tests/rinex_synth.py``: the test suite's known-position files; 3 600 epochs ≈ 2 MB); ``--file`` reads real files
instead (RTKLIB's ``convbin -v 2.11`` turns a receiver's log into RINEX 2.11).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from tollcli.readers.rinex import load_rinex, observations  # noqa: E402
from tollcli.readers.rinex_obs import observation_rows  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=3600)
    parser.add_argument("--file", nargs="*", default=None)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        files = args.file
        if not files:
            from rinex_synth import make_rinex

            files = []
            for version in (3, 2):
                (Path(tmp) / str(version)).mkdir()
                files.append(str(make_rinex(Path(tmp) / str(version), n_epochs=args.epochs, noise_m=0.5, seed=3, version=version)[0]))
        for path in files:
            t0 = time.perf_counter()
            direct = observation_rows(path)
            t_direct = time.perf_counter() - t0
            t0 = time.perf_counter()
            baseline = observations(load_rinex(path, "observation"))
            t_georinex = time.perf_counter() - t0
            same = direct is not None and direct.equals(baseline)
            version = open(path).read(9).strip()
            print(f"{Path(path).name} (RINEX {version}): {Path(path).stat().st_size / 1e6:.1f} MB, {len(baseline)} pseudoranges; direct "
                  f"{t_direct:.3f} s, georinex {t_georinex:.2f} s: ratio {t_direct / t_georinex:.4f}; rows "
                  f"{'identical' if same else 'DIFFERENT (or left to georinex)'}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
