"""Map NMEA satellite numbers to (constellation, system-native svid).

NMEA numbers satellites differently by version and receiver:

* NMEA ≤ 4.0 "extended" numbering in one space: 1–32 GPS, 33–64 SBAS
  (PRN = number + 87), 65–96 GLONASS (slot = number − 64), 193–202 QZSS
  (PRN = number − 192), u-blox 301–336 Galileo, 401–437 BeiDou; some receivers
  201–263 BeiDou.
* NMEA 4.10+ talker- or system-id scoped numbering: Galileo 1–36, BeiDou 1–63,
  QZSS 1–10 under their own talkers (GA, GB/BD, GQ/QZ) or GSA/GRS system id.

The key used to join GSA "used", GSV view and GRS residuals is
``(constellation, svid)`` after this mapping.
"""

from __future__ import annotations

GPS = "GPS"
GLONASS = "GLONASS"
GALILEO = "Galileo"
BEIDOU = "BeiDou"
QZSS = "QZSS"
NAVIC = "NavIC"
SBAS = "SBAS"
UNKNOWN = "unknown"

CONSTELLATIONS = (GPS, GLONASS, GALILEO, BEIDOU, QZSS, NAVIC, SBAS, UNKNOWN)

#: talker id → constellation hint (None: the number range decides)
TALKER_CONSTELLATION = {
    "GP": None,  # GPS talker also carries SBAS (33-64) and sometimes QZSS/GLONASS numbers
    "GN": None,
    "GL": GLONASS,
    "GA": GALILEO,
    "GB": BEIDOU,
    "BD": BEIDOU,
    "GQ": QZSS,
    "QZ": QZSS,
    "GI": NAVIC,
}

#: NMEA 4.10+ GNSS system id (GSA, GRS, GBS) → constellation
SYSTEM_ID_CONSTELLATION = {1: GPS, 2: GLONASS, 3: GALILEO, 4: BEIDOU, 5: QZSS, 6: NAVIC}


def by_number(prn: int) -> tuple[str, int]:
    """Constellation and svid from the one-space extended numbering."""
    if 1 <= prn <= 32:
        return GPS, prn
    if 33 <= prn <= 64:
        return SBAS, prn + 87
    if 65 <= prn <= 96:
        return GLONASS, prn - 64
    if 120 <= prn <= 158:
        return SBAS, prn
    if 193 <= prn <= 202:
        return QZSS, prn - 192
    if 201 <= prn <= 263:
        return BEIDOU, prn - 200
    if 301 <= prn <= 336:
        return GALILEO, prn - 300
    if 401 <= prn <= 463:
        return BEIDOU, prn - 400
    return UNKNOWN, prn


def satellite_id(hint: str | None, prn: int) -> tuple[str, int]:
    """(constellation, svid) for satellite number ``prn`` under constellation ``hint``.

    ``hint`` comes from the talker id or the NMEA 4.10 system id; ``None`` means
    the number alone decides.
    """
    if hint is None or hint == GPS:
        return by_number(prn)
    if hint == GLONASS:
        if 65 <= prn <= 96:
            return GLONASS, prn - 64
        if 1 <= prn <= 32:
            return GLONASS, prn
        return by_number(prn)
    if hint == GALILEO:
        if 1 <= prn <= 36:
            return GALILEO, prn
        return by_number(prn)
    if hint == BEIDOU:
        if 1 <= prn <= 63:
            return BEIDOU, prn
        if 201 <= prn <= 263:
            return BEIDOU, prn - 200
        return by_number(prn)
    if hint == QZSS:
        if 1 <= prn <= 10:
            return QZSS, prn
        return by_number(prn)
    if hint == NAVIC:
        return NAVIC, prn
    return by_number(prn)
