"""The shared vocabularies of the simulated processes and their gaps (pure Python, no numpy/jax).

The Monte-Carlo engine (:mod:`drip_cert.sim.config`) simulates these processes, and
``validate --data`` (:mod:`drip_cert.validate.data`) reads recorded ones by the same names; both
import them from here, so the command line can name them without loading jax.
"""

from __future__ import annotations

__all__ = ["DEFAULT_SCENARIOS", "GAPS", "SCENARIOS"]

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
