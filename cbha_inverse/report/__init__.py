"""Benchmarks and reports: error against run time, numerical stability."""
