"""The command-line layer: option parsing only; the work is in the rooms below.

Uses every room; nothing imports it but ``tollcli.__main__``.
"""
