"""For people: figures (matplotlib) and a self-contained HTML audit page of a charging run.

Uses the job and every room below it.
"""
