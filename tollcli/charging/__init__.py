"""Charging: geo-objects (build, check, compiled store), recognition, tariffs, invoices, audit.

Turns positions the integrity room vouches for into charged passages and money.
Uses integrity, GNSS, the readers and the floor (not enforcement, its neighbour).
"""
