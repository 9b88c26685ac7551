"""Integrity checks of each epoch: WLSR RAIM (``raim.py``, classic and ETC), FDE, threshold design,
speed (Doppler) and map-matching integrity, the Kalman HIT, and the policies that combine them.

Plain functions over the GNSS room's measurements and epoch tables; never prints.
Uses GNSS, the readers and the floor.
"""
