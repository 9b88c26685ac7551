"""The job: one log end to end (read → integrity → findings → recognition → invoice, streamed on a
sliding tail), verification by re-running it, the integrity tables of a log, and many logs at once.

Uses charging, enforcement, integrity, GNSS, the readers and the floor.
"""
