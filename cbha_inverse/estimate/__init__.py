"""Estimation of the arm's shape from its own sensors (``docs/proprioception.md``)."""
