"""The compiled kernels of the bulk reader (``_bulk_kernels.c``), or None where they were not built.

Set ``TOLLCLI_KERNELS=numpy`` to use the numpy versions (the same tables, slower):
for cross-checking, and what an install without a C compiler gets.
"""

from __future__ import annotations

import os

compiled = None
if os.environ.get("TOLLCLI_KERNELS", "").lower() != "numpy":
    try:
        from tollcli.nmea import _bulk_kernels as compiled
    except ImportError:  # built without a C compiler: the numpy kernels
        compiled = None
