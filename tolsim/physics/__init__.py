"""Physics layer: pure functions and Numba kernels (numpy, scipy and numba only)."""
