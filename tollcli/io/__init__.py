"""Input and output plumbing: sources (paths, .gz, stdin) and atomic table writers."""
