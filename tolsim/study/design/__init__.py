"""Studies of studies: what-if sweeps and tolerance allocation."""
