"""Where a study runs: chunks, checkpoints, saved samples, backends (inline, processes,
dask)."""
