"""Constants of a system: growth, Lipschitz and Hoelder bounds of the uncertainty and the closed
loops (symbolic rewrites, interval branch and bound over expressions, sampled estimates), the
input constants, and the nominal process's moment constants (docs/math/l1drac.md section 2,
contraction.md section 6).

Import from the modules (``drip_cert.analysis.growth.constants``, ``.regularity``, ...): this
package imports nothing.
"""
