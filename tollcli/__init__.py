"""tollcli — GNSS road-user charging log processor.

Data flows one way: read → epochs → integrity → charging → reports, and the
packages are rooms in that order, each importing only from the rooms below it:
the floor (``errors``, ``times``, ``cache``, ``geodesy``, ``spatial``, ``stats``, ``io/``)
→ ``readers/`` → ``gnss/`` → ``integrity/`` → ``charging/`` and ``enforcement/``
→ ``job/`` and ``simulate/`` → ``report/`` → ``cli/`` (docs/architecture.md;
``tests/test_layering.py`` keeps it true).
"""

__version__ = "0.1.0"
