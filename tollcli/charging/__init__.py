"""Charging: recognition of passages, tariffs and per-km rate tables, money, invoices, the audit.

Turns positions the integrity room vouches for into charged passages and money, over the geo-objects of
``tollcli.geoobjects``. Uses integrity, GNSS, the readers, the geo-objects and the floor (not enforcement, its neighbour).
"""
