"""Readable numpy versions of the package's equations: independent references for the tests."""
