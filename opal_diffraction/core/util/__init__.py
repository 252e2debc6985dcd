"""Small tools every room may use: enumerations, triangle geometry, cancellation, BLAS threads, the JIT of the
compiled kernels and their switch (jit.py), per-row scatter sums (row_sums.py). Imports no other room."""
