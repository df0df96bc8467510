"""Bounds on networks and policies: the MLP enclosures (``mlp/``: values, Jacobians, Clarke
Jacobians, second derivatives over boxes), block enclosures inside expressions, and the policy
regularity constants TaSIL needs (docs/math/tasil.md, nonsmooth.md).

Import from the modules: this package imports nothing.
"""
