"""NMEA 0183 reading: sentences → columnar epoch and satellite tables."""

from tollcli.nmea.reader import NmeaTables, ReadStats, iter_nmea_tables, read_nmea

__all__ = ["NmeaTables", "ReadStats", "iter_nmea_tables", "read_nmea"]
