"""GNSS: broadcast orbits, atmosphere, WLS positioning, error models, and the measurement arrays the RAIM reads.

Turns the readers' tables into positions and :class:`~tollcli.gnss.measurements.Measurements`.
Uses the readers and the floor.
"""
