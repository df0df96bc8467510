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


def test_spec_coordinates_left_unfinished_when_they_cannot_be_chosen(monkeypatch):
    """The pendulum's expert does not contract in x (DRIP-A2 fails, exact), so its verdict in x
    is not_certified whatever else it holds; a certified candidate in z beats that, and x's
    constants, TaSIL and L1-DRAC parts are not computed. The certificate returned is the one
    returned when x is finished (x forced through by a DRIP-A2 check that holds)."""
    import dataclasses

    import drip_cert.bounds.certificate as C

    systems = []
    real = C._constants_part

    def counting(s, settings, stage):
        systems.append(s)
        return real(s, settings, stage)

    monkeypatch.setattr(C, "_constants_part", counting)
    lazy = certify(PENDULUM)
    assert lazy.coordinates is not None and lazy.verdict.value == "certified"
    assert len(systems) == 2  # the two metric candidates; not x
    x = [a for a in lazy.alternatives if a["coordinates"] == "x"]
    assert len(x) == 1 and x[0]["verdict"] == "not_certified" and x[0]["failing"] == 1
    assert x[0]["verdict_reasons"][0].startswith("DRIP-A2 fails")
    assert "not finished" in x[0]["verdict_reasons"][-1]

    real_check = C._expert_rate_check

    def holding(s, opts, ce):  # pretend DRIP-A2 holds in x: x is finished as before
        return dataclasses.replace(real_check(s, opts, ce), holds=True)

    monkeypatch.setattr(C, "_expert_rate_check", holding)
    systems.clear()
    full = certify(PENDULUM)
    assert len(systems) == 3  # x too
    x_full = [a for a in full.alternatives if a["coordinates"] == "x"]
    assert x_full[0]["verdict"] == "not_certified" and x_full[0]["failing"] > 1
    a, b = lazy.to_dict(), full.to_dict()
    for d in (a, b):
        d.pop("timings", None)
        d["coordinates"].pop("alternatives")
    assert a == b


def test_spec_coordinates_finished_when_no_candidate_beats_them(tmp_path):
    """When every candidate in z is not_certified too, x could still be the choice: it is
    finished (all its failing checks counted), as before."""
    from drip_cert.spec import load_spec

    text = PENDULUM.read_text()
    pol = 'learned = ["9.81*sin(q) - 3.96*q - 4.04*q_dot"]'
    assert pol in text and "heldout = 100" in text
    path = tmp_path / "pendulum.toml"  # TaSIL fails everywhere (tests/test_coordinates.py)
    path.write_text(
        text.replace("heldout = 100", "heldout = 20").replace(
            pol, 'learned = ["9.81*sin(q) - 3.96*q - 4.04*q_dot + 0.01*sin(q_dot)"]'
        )
    )
    cert = certify(load_spec(path))
    assert cert.verdict.value == "not_certified" and cert.coordinates is not None
    x = [a for a in cert.alternatives if a["coordinates"] == "x"]
    assert x[0]["verdict"] == "not_certified" and x[0]["failing"] > 1
    assert not any("not finished" in r for r in x[0]["verdict_reasons"])
