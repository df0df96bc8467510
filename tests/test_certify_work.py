"""Work done once per ``certify``: the expert demonstrations are drawn once for the spec's own
coordinates and every metric candidate (each candidate maps the same draw to its z = Theta x)."""

from __future__ import annotations

from pathlib import Path

import drip_cert.learn.imitation as imitation
from drip_cert.bounds.certificate import certify

PENDULUM = Path(__file__).resolve().parents[1] / "examples" / "pendulum" / "pendulum.toml"
VAN_DER_POL = PENDULUM.parents[1] / "van_der_pol" / "van_der_pol.toml"


def test_demonstrations_drawn_once_for_all_metric_candidates(monkeypatch):
    calls = []
    real = imitation.demonstration_set

    def counting(s, settings):
        calls.append(settings.seed)
        return real(s, settings)

    monkeypatch.setattr(imitation, "demonstration_set", counting)
    cert = certify(PENDULUM)
    # the pendulum has no Euclidean rate: the certificate is computed in z for two metrics
    assert cert.coordinates is not None and len(cert.alternatives) == 2
    assert len(calls) == 1


def test_jitted_jacobian_built_once_per_model(monkeypatch):
    from drip_cert._jax import jax
    from drip_cert.bounds.certificate import analyse_contraction
    from drip_cert.spec.load import as_spec

    spec = as_spec(VAN_DER_POL)
    s, opts = spec.system, spec.settings.contraction
    m = s.numeric
    assert m.jac_batched("expert") is m.jac_batched("expert")
    jits = []
    real = jax.jit

    def counting(*a, **k):
        jits.append(a)
        return real(*a, **k)

    monkeypatch.setattr(jax, "jit", counting)
    first = analyse_contraction(s, "expert", opts)
    second = analyse_contraction(s, "expert", opts)
    # the second analysis of the same model reuses the jitted Jacobian (no new jit, no retrace)
    assert jits == []
    assert first.euclidean.rate == second.euclidean.rate
