"""The command-line layer: option parsing only; the work is in the stage modules."""
