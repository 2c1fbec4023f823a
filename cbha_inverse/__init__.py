"""
Quasi-static FEM modelling and inverse control of continuum robots with rigid vertebrae.

The package implements Bosman et al., ICRA 2015 for Festo's Compact Bionic Handling Assistant:
``core`` (mechanics, BTD solver, inverse QP), ``fem`` (offline condensation), ``ros`` (nodes).
"""

__version__ = '0.1.0'
