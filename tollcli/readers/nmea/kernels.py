"""The compiled kernels of the bulk reader (``_bulk_kernels.c``), or None where they were not built.

Set ``TOLLCLI_KERNELS=numpy`` to use the numpy versions (the same tables, slower):
for cross-checking, and what an install without a C compiler gets. Found as every compiled module of the package
is (:func:`tollcli.kernels.compiled_module`: an installed copy's where a source checkout shadows it).
"""

from __future__ import annotations

from tollcli.kernels import compiled_module

compiled = compiled_module("tollcli.readers.nmea._bulk_kernels")
