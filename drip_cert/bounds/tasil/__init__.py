"""The TaSIL certificate: a bound on the policy-induced imitation gap (rho_TaSIL),
docs/math/tasil.md sections 3 and 4, **a construction of this project, not TaSIL's own
constant** (every report carries :data:`LABEL`).

Modules, each importing only the ones before it:

* :mod:`~drip_cert.bounds.tasil.trajectory` -- the trajectory quantities ``h_0``, ``h_1`` (A3;
  sound continuous-time sups, section 4);
* :mod:`~drip_cert.bounds.tasil.lemma` -- the deterministic imitation-gap lemma and ``eps*``
  (section 3.1, Proposition 4.1);
* :mod:`~drip_cert.bounds.tasil.forms` -- the statistical forms: held-out (Clopper-Pearson),
  threshold, expectation and DRIP-shaped ``rho_TaSIL`` (sections 3.3-3.4);
* :mod:`~drip_cert.bounds.tasil.certificate` -- :class:`TasilCertificate` and
  :func:`tasil_certificate`;
* :mod:`~drip_cert.bounds.tasil.section` -- the TaSIL section of a system's certificate (the h's
  along simulated expert trajectories, ``L_Delta``, the tube radius); it needs jax and is not
  re-exported here.
"""

from __future__ import annotations

from drip_cert.bounds.tasil.certificate import (
    ASSUMPTIONS,
    LABEL,
    TasilCertificate,
    tasil_certificate,
)
from drip_cert.bounds.tasil.forms import (
    FORMS,
    ClassConstants,
    TasilForm,
    parametric_epsilon,
    parametric_expectation,
    rho_tasil,
)
from drip_cert.bounds.tasil.lemma import GapLemma, eps_star, imitation_gap_lemma
from drip_cert.bounds.tasil.trajectory import (
    TrajectoryH,
    h_continuous,
    h_discrete,
    h_from_functions,
)

__all__ = [
    "ASSUMPTIONS",
    "FORMS",
    "LABEL",
    "ClassConstants",
    "GapLemma",
    "TasilCertificate",
    "TasilForm",
    "TrajectoryH",
    "eps_star",
    "h_continuous",
    "h_discrete",
    "h_from_functions",
    "imitation_gap_lemma",
    "parametric_epsilon",
    "parametric_expectation",
    "rho_tasil",
    "tasil_certificate",
]
