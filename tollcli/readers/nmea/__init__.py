"""NMEA 0183 reading: sentences → columnar epoch and satellite tables (bulk path and per-line reference).

Part of the readers room: uses only the floor (errors, io).
"""

from tollcli.readers.nmea.line_reader import ReadStats
from tollcli.readers.nmea.reader import NmeaTables, iter_nmea_tables, read_nmea

__all__ = ["NmeaTables", "ReadStats", "iter_nmea_tables", "read_nmea"]
