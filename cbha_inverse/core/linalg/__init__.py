"""Block-tridiagonal linear algebra of the frame chain and its LAPACK / dense comparisons."""
