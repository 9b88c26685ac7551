"""tollcli — GNSS road-user charging log processor.

Data flows one way: read → epochs → integrity → charging → reports.
"""

__version__ = "0.1.0"
