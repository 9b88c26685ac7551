"""The compiled kernels of the bulk reader (``_bulk_kernels.c``), or None where they were not built.

Set ``TOLLCLI_KERNELS=numpy`` to use the numpy versions (the same tables, slower):
for cross-checking, and what an install without a C compiler gets. When the
package is imported from a source checkout that shadows the installed copy (tests
run from the repository after ``pip install .``), the installed copy's compiled
module is used.
"""

from __future__ import annotations

import os


def _installed_copy():
    """The compiled module of an installed copy further down ``sys.path``, loaded from its file (None when absent)."""
    import importlib.machinery
    import importlib.util
    import sys

    for entry in sys.path:
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = os.path.join(entry or ".", "tollcli", "readers", "nmea", f"_bulk_kernels{suffix}")
            if os.path.isfile(path):
                spec = importlib.util.spec_from_file_location("tollcli.readers.nmea._bulk_kernels", path)
                module = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(module)
                return module
    return None


compiled = None
if os.environ.get("TOLLCLI_KERNELS", "").lower() != "numpy":
    try:
        from tollcli.readers.nmea import _bulk_kernels as compiled
    except ImportError:  # not built here: the installed copy's, else the numpy kernels
        try:
            compiled = _installed_copy()
        except (ImportError, OSError):
            compiled = None
