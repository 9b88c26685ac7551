"""Readers of receiver data: NMEA 0183 (``nmea/``), the GSDC derived CSV, RINEX files, GPS time.

Files in, columnar tables out; a reader knows nothing of positioning, integrity or tariffs.
Uses only the floor (errors, io, times).
"""
