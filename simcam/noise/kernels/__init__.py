"""Sampling kernels of the noise models: :mod:`.vectorised` (exact float32 normal and Poisson
samplers in numpy), :mod:`.poisson` (the Poisson-Gaussian numba kernel with alias tables and the
ziggurat normal) and :mod:`.nlf` (the fused NLF numba kernels)."""
