"""Contraction: log norms, the rate routes (exact, branch and bound, sampled; the learned loop's
global routes and the slope-restricted LMI), LMI metrics, coordinate changes ``z = Theta x`` and
forward-invariant sets (docs/math/contraction.md).

Import from the modules (``drip_cert.analysis.contraction.rate``, ``.lmi``, ...): this package
imports nothing, so that a light module does not pull in cvxpy or jax.
"""
