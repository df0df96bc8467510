"""What was certified, as objects for the user's own loop: the L1-DRAC controller and the policy.

:func:`l1drac_controller` builds the :class:`~drip_cert.control.controller.L1DRACController` of a
certificate's L1-DRAC design (``omega``, ``lambda_s``, ``T_s``) around the certified learned
policy; :func:`learned_policy` returns that policy as a plain callable ``x -> u``. A simulator or
robot loop that calls them runs exactly what the certificate is about; record its trajectories
(``docs/data_format.md``) with ``controller.fingerprint`` (or ``policy.fingerprint`` for data of
the policy alone) and check them with ``drip-cert validate SPEC --data FILE``, which refuses data
whose fingerprint is not the certificate's.

Example::

    import numpy as np
    from drip_cert.deploy import l1drac_controller, learned_policy

    controller = l1drac_controller("examples/pendulum/pendulum.toml")   # certifies the spec
    policy = learned_policy("examples/pendulum/pendulum.toml")          # pi_IL: x -> u
    controller.reset(x0)
    for j in range(n_steps):
        u = controller.step(j * controller.dt, x)                      # pi_IL(x) + U_L1
        x = my_simulator_step(x, u, controller.dt)
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

from drip_cert.bounds.certificate import Certificate, certify
from drip_cert.errors import SpecError
from drip_cert.model.fingerprint import Fingerprint, policy_fingerprint
from drip_cert.model.system import System
from drip_cert.spec.load import Spec, SpecSource, as_spec

if TYPE_CHECKING:
    from drip_cert.bounds.certificate import Certificate
    from drip_cert.control.controller import L1DRACController, PolicyFunction

__all__ = ["l1drac_controller", "learned_policy"]


def _spec(source: SpecSource) -> Spec:
    # a path, a Spec or a System alike; a certificate is taken before this
    return as_spec(source, argument="source", also="a drip_cert.Certificate")


def certificate_of(source: SpecSource | Certificate, progress: bool = False) -> Certificate:
    """The certificate of ``source``: itself when it is one, else the spec's (certified now).

    Raises
    ------
    SpecError
        When the spec has no learned policy (the controller wraps the certified one).
    """
    if isinstance(source, Certificate):
        return source
    spec = _spec(source)
    if spec.system.learned is None:
        raise SpecError(
            "the spec has no learned policy, so there is nothing certified to deploy: add "
            "[policy] learned (e.g. the `use_in_spec` lines `drip-cert train` writes)",
            field="policy.learned",
        )
    return certify(spec, progress=progress)


def l1drac_controller(
    source: SpecSource | Certificate,
    *,
    dt: float | None = None,
    progress: bool = False,
) -> L1DRACController:
    """The certified L1-DRAC controller (with the learned policy) for the user's loop.

    Parameters
    ----------
    source
        A spec file or :class:`~drip_cert.spec.load.Spec` with a learned policy (certified here:
        seconds), or a :class:`~drip_cert.bounds.certificate.Certificate`.
    dt
        The loop's step; must divide the certified ``T_s`` (``T_s = k dt``). Default: the
        spec's ``[simulation] dt`` rounded down to ``T_s / k`` as ``drip-cert validate`` does
        (``T_s`` itself when ``source`` is a certificate).
    progress
        Progress lines of the certification on stderr.

    Returns
    -------
    L1DRACController
        With ``omega``, ``lambda_s``, ``T_s`` of the certificate's design, the certificate's
        system (in its coordinates ``z = Theta x`` when it has them; the controller maps the
        measured ``x``), its verdict in ``controller.verdict`` and its fingerprint (policy and
        design) in ``controller.fingerprint``: write it into the recorded data.

    Raises
    ------
    SpecError
        No learned policy, no feasible L1-DRAC design, or a ``dt`` that does not divide ``T_s``.
    """
    from drip_cert.control.controller import (  # jax: keep off the CLI start-up path
        L1DRACController,
    )
    from drip_cert.control.l1drac import L1Params  # jax: keep off the CLI start-up path

    cert = certificate_of(source, progress=progress)
    l1 = cert.l1
    d = None if l1 is None else l1.design
    if d is None or not d.feasible or d.omega is None or d.lambda_s is None or d.Ts is None:
        if l1 is None:
            why = "no [l1drac] table"
        else:  # no design at all (an assumption failed before the designer ran): l1.error
            why = (l1.error if d is None else d.reason) or "infeasible"
        raise SpecError(
            f"the certificate has no feasible L1-DRAC design ({why}): there is no certified "
            "controller to deploy",
            field="l1drac",
        )
    if dt is None:
        if isinstance(source, str | os.PathLike | Spec | System):
            sim_dt = _spec(source).settings.simulation.dt
            dt = d.Ts / max(1, math.ceil(d.Ts / sim_dt))
        else:
            dt = d.Ts
    params = L1Params(d.omega, d.lambda_s, d.Ts, float(dt))
    theta = None if cert.coordinates is None else cert.coordinates.theta
    return L1DRACController(
        cert.system.numeric,
        params,
        theta=theta,
        verdict=cert.verdict.value,
        fingerprint=cert.fingerprint,
    )


def learned_policy(source: SpecSource | Any) -> PolicyFunction:
    """The learned policy ``pi_IL`` of a spec (or certificate) as a plain callable ``x -> u``.

    ``source`` is a spec file, a :class:`~drip_cert.spec.load.Spec`, a
    :class:`~drip_cert.model.system.System` or a certificate (its user-coordinate policy is
    the spec's: the certificate's ``system`` may be in ``z``, so pass the spec for ``x``).
    ``policy.fingerprint`` is the policy part of the certificate's fingerprint (``design``
    ``None``): data recorded with the policy alone (no L1-DRAC) may carry it.
    """
    from drip_cert.control.controller import PolicyFunction  # jax: keep off the CLI start-up path

    if isinstance(source, System):
        s = source
    elif getattr(source, "coordinates", "absent") is None and hasattr(source, "system"):
        s = source.system  # a certificate in the user's coordinates
    elif hasattr(source, "coordinates") and hasattr(source, "system"):
        raise SpecError(
            "this certificate is in the coordinates z = Theta x: pass the spec for the policy "
            "in the user's x",
            field="source",
        )
    else:
        s = as_spec(
            source, argument="source", also="a certificate in the user's coordinates"
        ).system
    fp = Fingerprint(policy=policy_fingerprint(s))
    return PolicyFunction(s.numeric, name=s.name, fingerprint=fp)
