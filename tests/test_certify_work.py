"""Work done once per ``certify``: the expert demonstrations are drawn once for the spec's own
coordinates and every metric candidate (each candidate maps the same draw to its z = Theta x)."""

from __future__ import annotations

from pathlib import Path

import drip_cert.learn.imitation as imitation
from drip_cert.bounds.certificate import certify

PENDULUM = Path(__file__).resolve().parents[1] / "examples" / "pendulum" / "pendulum.toml"


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
