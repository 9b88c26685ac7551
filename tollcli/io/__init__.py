"""The floor's plumbing: sources (paths, .gz, stdin, format sniffing) and atomic table and text writers.

Uses nothing of tollcli but ``tollcli.errors``; every room may use it.
"""
