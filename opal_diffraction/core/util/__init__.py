"""Small tools every room may use: enumerations, triangle geometry, cancellation, BLAS threads. Imports no other room."""
