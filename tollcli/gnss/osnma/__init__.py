"""Galileo OSNMA — navigation message authentication (OSNMA SIS ICD 1.1, receiver guidelines 1.3).

Read in this order: :mod:`.pages` (I/NAV pages from the ICD test-vector CSV or u-blox RXM-SFRBX, with the
GST each page began at), :mod:`.dsm` (HKROOT → digital signature messages: the public key checked against
the Merkle root, the root key against its ECDSA signature), :mod:`.tesla` (the key chain, the MAC functions
and the MAC look-up table), :mod:`.navdata` (the navigation data each ADKD covers, with the Reed-Solomon
recovery of CED words), :mod:`.mack` (MACK messages → tags and keys), :mod:`.receiver` (the state machine
over pages that ties them together and returns tables of what it verified and what failed) and
:mod:`.satellite_status` (those tables → per epoch and satellite whether its navigation data are
authenticated).

Authentication covers data, not ranging: a verified tag proves the ephemeris, clock and status words came
from the Galileo system, not that the signal they rode on was not replayed or delayed (docs/osnma.md).

Part of the GNSS room: uses the readers (GPS time, byte sources), the I/NAV CRC of :mod:`tollcli.gnss.inav_words`
and the floor.
"""
