"""Many logs at once: a local process pool or a Dask cluster, resumable, one bad log never stops the others."""
