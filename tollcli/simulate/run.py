"""Simulate a drive into a folder: the logs, the truth and a manifest.

Files written (each atomically):

``drive.nmea``          the receiver's NMEA log
``drive-derived.csv``   the same measurements as a GSDC derived CSV (full WLS path)
``truth.csv``           the true trajectory (time, position, speed, heading, fault flag)
``truth-geoobjects.json`` the geo-objects really driven (with ``geo``): ids, as ``audit --truth`` reads
``drive-librsf.txt``, ``truth-librsf.txt``  with odometry: the pseudoranges and the odometry as libRSF text (the
                        smartLoc layout of the real Berlin drive), and the truth as its ``point3`` lines
``manifest.json``       the settings, the command, counts and every file's SHA-256

No wall-clock time is written anywhere: the same settings and seed give the same bytes.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import asdict

import numpy as np

from tollcli import __version__
from tollcli.charging.invoice import file_sha256
from tollcli.io.writers import AtomicText, TableWriter, output_folder, write_text_atomic
from tollcli.simulate.drive import SimConfig, simulate
from tollcli.simulate.logs import gsdc_rows, librsf_lines, librsf_truth_lines, nmea_lines, truth_rows
from tollcli.simulate.route import Trajectory

FILES = ("drive.nmea", "drive-derived.csv", "truth.csv")
LIBRSF_FILES = ("drive-librsf.txt", "truth-librsf.txt")


def write_drive(traj: Trajectory, config: SimConfig, outdir: str, geo: str | None = None, command: str = "",
                progress=None) -> dict:  # fmt: skip
    """Simulate and write the drive's files into ``outdir``; returns the manifest."""
    output_folder(outdir)
    names = FILES + (LIBRSF_FILES if config.odometry else ())
    path = {name: os.path.join(outdir, name) for name in names}
    counts = {"epochs": 0, "fixes": 0, "faulty_epochs": 0, "satellite_rows": 0}
    visible = []
    with AtomicText(path["drive.nmea"]) as nmea, TableWriter(path["drive-derived.csv"], "csv") as gsdc, \
            TableWriter(path["truth.csv"], "csv") as truth, contextlib.ExitStack() as extra:  # fmt: skip
        librsf = [extra.enter_context(AtomicText(path[name])) for name in LIBRSF_FILES] if config.odometry else None
        for chunk in simulate(traj, config):
            nmea.writelines(nmea_lines(chunk.epochs, chunk.satellites))
            if librsf is not None:
                librsf[0].writelines(librsf_lines(chunk.epochs, chunk.satellites, config))
                librsf[1].writelines(librsf_truth_lines(chunk.epochs))
            gsdc.write(gsdc_rows(chunk.epochs, chunk.satellites))
            truth.write(truth_rows(chunk.epochs))
            counts["epochs"] += len(chunk.epochs)
            counts["fixes"] += int(chunk.epochs["fix"].sum())
            counts["faulty_epochs"] += int(chunk.epochs["faulty"].sum())
            counts["satellite_rows"] += len(chunk.satellites)
            visible.append(chunk.epochs["n_used"].to_numpy())
            if progress is not None:
                progress(len(chunk.epochs))
        nmea.commit()
        gsdc.commit()
        truth.commit()
        for out in librsf or ():
            out.commit()
    files = list(names)
    if geo is not None:
        from tollcli.charging.audit import driven_from_truth
        from tollcli.charging.recognition import load_geoobjects
        from tollcli.geoobjects.city import is_city_file
        from tollcli.spatial import read_features

        if is_city_file(read_features(geo)):  # gantries crossed and zones entered
            from tollcli.charging.city_audit import driven_city_objects
            from tollcli.charging.truth_passages import truth_trajectory
            from tollcli.geoobjects.city import load_city_network

            driven = driven_city_objects(load_city_network(geo), truth_trajectory(path["truth.csv"]))
        else:
            driven = sorted(driven_from_truth(path["truth.csv"], load_geoobjects(geo)))
        write_text_atomic(os.path.join(outdir, "truth-geoobjects.json"), json.dumps(driven, indent=1) + "\n")
        files.append("truth-geoobjects.json")
    n_vis = np.concatenate(visible) if visible else np.zeros(0)
    settings = asdict(config)
    settings["start_utc"] = config.start_utc.isoformat().replace("+00:00", "Z")
    manifest = {
        "tool": f"tollcli {__version__}",
        "command": command,
        "settings": settings,
        "geoobjects": geo,
        "counts": counts,
        "visible_satellites": {f"ge{k}": float(np.mean(n_vis >= k)) if n_vis.size else 0.0 for k in (4, 5, 6, 7)},
        "files": {name: file_sha256(os.path.join(outdir, name)) for name in files},
    }
    write_text_atomic(os.path.join(outdir, "manifest.json"), json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return manifest
