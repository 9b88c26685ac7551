"""Regenerate the bundled samples: ``python samples/make_samples.py`` (deterministic).

* ``straight-drive.nmea``: 180 s of a 50 km/h GPS+Galileo drive near Perpignan
  (NMEA 4.10: RMC, VTG, GGA, GSA with system ids, GSV with signal ids, GST), with
  a comment header and one sentence whose checksum was damaged in transit, so
  the reader's skip report has something to say.
"""

from pathlib import Path

from tollcli.nmea.compose import straight_drive

HERE = Path(__file__).resolve().parent


def main() -> None:
    lines = list(straight_drive(180))
    damaged = 100
    lines[damaged] = lines[damaged][:-2] + ("00" if lines[damaged][-2:] != "00" else "01")
    header = [
        "# tollcli sample: straight drive, 180 epochs at 1 Hz, 13.9 m/s, course 45 deg",
        "# made by samples/make_samples.py; line 103 has a damaged checksum on purpose",
    ]
    (HERE / "straight-drive.nmea").write_text("\n".join(header + lines) + "\n", encoding="ascii")


if __name__ == "__main__":
    main()
