"""Force terms: pure kernels over flat arrays, accumulated into one (N, 3) array."""
