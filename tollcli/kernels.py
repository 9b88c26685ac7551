"""The package's optional compiled modules (C twins of pure-Python or numpy kernels), or None where not built.

``pip install`` compiles them when the machine has a C compiler (``setup.py``, ``optional=True``); without one the
package uses the Python versions of the same kernels, which give the same results, slower. Set
``TOLLCLI_KERNELS=numpy`` to use those (for cross-checking). When the package is imported from a source checkout
that shadows the installed copy (tests run from the repository after ``pip install .``), the installed copy's
compiled module is used.
"""

from __future__ import annotations

import importlib
import os


def _installed_copy(dotted: str):
    """The compiled module ``dotted`` of an installed copy further down ``sys.path``, loaded from its file (None when absent)."""
    import importlib.machinery
    import importlib.util
    import sys

    parts = dotted.split(".")
    for entry in sys.path:
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = os.path.join(entry or ".", *parts[:-1], parts[-1] + suffix)
            if os.path.isfile(path):
                spec = importlib.util.spec_from_file_location(dotted, path)
                module = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(module)
                return module
    return None


def compiled_module(dotted: str):
    """The compiled module ``dotted`` (e.g. ``tollcli.integrity._trajectory_kernel``), or None: not built, or
    ``TOLLCLI_KERNELS=numpy``."""
    if os.environ.get("TOLLCLI_KERNELS", "").lower() == "numpy":
        return None
    try:
        return importlib.import_module(dotted)
    except ImportError:  # not built here: the installed copy's, else none
        try:
            return _installed_copy(dotted)
        except (ImportError, OSError):
            return None
