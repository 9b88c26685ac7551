"""Charging: geo-objects, recognition, tariffs and invoices."""
