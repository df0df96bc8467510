"""The shared vocabularies (pure Python, no numpy/jax): the simulated processes and their gaps,
and the routes of the contraction rate.

The Monte-Carlo engine (:mod:`drip_cert.sim.config`) simulates these processes, and
``validate --data`` (:mod:`drip_cert.validate.data`) reads recorded ones by the same names; both
import them from here, so the command line can name them without loading jax. The contraction
routes are implemented in :data:`drip_cert.analysis.contraction.rate.ROUTES` and offered by the
settings (``[contraction] method``) under these names.
"""

from __future__ import annotations

__all__ = [
    "CONTRACTION_AUTO",
    "CONTRACTION_METHODS",
    "CONTRACTION_ROUTES",
    "CONTRACTION_ROUTE_NAMES",
    "DEFAULT_SCENARIOS",
    "GAPS",
    "SCENARIOS",
]

SCENARIOS = (
    "expert_nominal",
    "learned_nominal",
    "learned_true",
    "learned_l1_true",
    "nominal_sde",
)
"""Every process the engine can simulate. ``nominal_sde`` is L1-DRAC's nominal process (4b) when
the known diffusion ``p`` is not zero: ``dX* = (f + g pi_IL)(t, X*) dt + p(t, X*) dW`` from
``xi ~ D``, driven by the Brownian path of the true processes (a synchronous coupling)."""

DEFAULT_SCENARIOS = SCENARIOS[:4]
"""The four processes of the DRIP paper (the default of ``SimConfig.scenarios``)."""

GAPS = (
    # name, process a, process b: r_t = ||a_t - b_t||
    ("policy", "learned_nominal", "expert_nominal"),
    ("total_true", "learned_true", "expert_nominal"),
    ("uncertainty_true", "learned_true", "learned_nominal"),
    ("total_l1", "learned_l1_true", "expert_nominal"),
    ("uncertainty_l1", "learned_l1_true", "learned_nominal"),
    # with a known diffusion p != 0, L1-DRAC's radius is a distance to the SDE (4b), not to x'
    ("uncertainty_true_sde", "learned_true", "nominal_sde"),
    ("uncertainty_l1_sde", "learned_l1_true", "nominal_sde"),
)
"""The gaps ``(name, a, b)``: ``r_t = ||a_t - b_t||``."""

CONTRACTION_ROUTES: tuple[tuple[str, str], ...] = (
    (
        "exact-linear",
        "a Jacobian constant in x and t: mu_2 = lambda_max(sym J) isolated exactly, for all x, t",
    ),
    (
        "mlp-bnb",
        "a sound bound on a box for J = A + sum_k C_k Dh_k(x) of MLP blocks (vectorised branch "
        "and bound of a centred linearisation, the remainder by Weyl)",
    ),
    (
        "interval-bnb",
        "a sound bound on a box (and a time range): interval enclosures of J, a Rohn-type bound "
        "of mu_2, branch and bound",
    ),
    (
        "sampled",
        "an estimate, never a bound: grid + random points + local search of max mu_2",
    ),
)
"""The routes of the Euclidean contraction rate (DRIP Assumption 2), ``(name, meaning)``, in the
order ``'auto'`` tries them (docs/math/contraction.md sections 2-3)."""

CONTRACTION_ROUTE_NAMES = tuple(name for name, _ in CONTRACTION_ROUTES)
"""The names of :data:`CONTRACTION_ROUTES`."""

CONTRACTION_AUTO = "auto"
"""The first route that applies, in the order of :data:`CONTRACTION_ROUTES`."""

CONTRACTION_METHODS = (CONTRACTION_AUTO, *CONTRACTION_ROUTE_NAMES)
"""The values of ``[contraction] method`` (``contraction_rate(method=...)``)."""
