"""Linear algebra of the frame chain: tangent factors, block-tridiagonal factorisation."""
