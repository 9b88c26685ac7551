"""Readers of receiver data: NMEA 0183 (``nmea/``), u-blox UBX, gpsd JSON, RTKLIB solutions, the GSDC derived CSV,
Android GnssLogger, RINEX, libRSF text, GPS time. (Road files are read by ``tollcli.geoobjects``.)

Files in, columnar tables out; a reader knows nothing of positioning, integrity or tariffs.
Uses only the floor (errors, io, times).
"""
