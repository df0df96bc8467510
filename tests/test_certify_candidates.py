"""Metric coordinate candidates ranked on a cheap bound, and only those that can win designed.

Mathematics first: the lower bound of :func:`~drip_cert.bounds.l1drac.lower.rho_lower_bound` is
below the smallest radii the searches find at every omega (both sides of 2 lambda) and below the
rho of full designs; then a natural-coordinate example in which one candidate cannot win is
certified with one L1-DRAC design fewer, the same choice and the skipped candidate listed.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import drip_cert.bounds.l1drac.system as l1system
from drip_cert.bounds.certificate import certify
from drip_cert.bounds.l1drac.appendix import reference_constants, true_constants
from drip_cert.bounds.l1drac.designer import design
from drip_cert.bounds.l1drac.lower import LOWER_DEFLATE, rho_lower_bound
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.bounds.l1drac.searches import min_rho_a, min_rho_r
from tests.helpers import EXAMPLES, di_constants, random_constants

#: omegas in multiples of lambda, on both sides of omega = 2 lambda (the bound's two cases)
OMEGA_MULTIPLES = (1e-4, 1e-2, 0.3, 1.0, 1.9, 2.1, 3.0, 10.0, 1e2, 1e4, 1e6)
#: the searches' radii are minimal to a relative 1e-12 (ROOT_RTOL): a bound may exceed a
#: found radius by that much without contradicting it
SEARCH_RTOL = 1e-9
#: the bound is a useful one: at least this fraction of the smallest radius found over omega
#: (the random sets of the test come out at 0.6 to 1.0; a bound of 0 would pass soundness)
TIGHT_FRACTION = 0.3

CART_POLE = EXAMPLES / "cart_pole" / "cart_pole.toml"


def _sets():
    rng = np.random.default_rng(20261127)
    return [di_constants(), *(random_constants(rng) for _ in range(6))]


@pytest.mark.parametrize("c", _sets())
def test_rho_lower_bound_below_the_smallest_radii_at_every_omega(c):
    p = 1
    rc, tc = reference_constants(c, p), true_constants(c, p)
    low = rho_lower_bound(c, p)
    found = []
    for k in OMEGA_MULTIPLES:
        w = k * float(c.lam)
        r = min_rho_r(c, rc, w, ("16a", "21a"))
        if r is None:
            continue
        a = min_rho_a(c, tc, p, w, r, None, None, ("16b",))
        assert a is not None
        found.append(r + a)
        assert low <= (r + a) * (1.0 + SEARCH_RTOL), (k, low, r + a)
    assert found
    assert low >= TIGHT_FRACTION * min(found) > 0.0


def test_rho_lower_bound_below_a_full_design():
    c = di_constants()
    d = design(c, DesignRequest(p=1, Ts=1e-3, objective="rho_at_Ts", front=False))
    assert d.feasible and d.rho is not None
    assert rho_lower_bound(c, 1) <= d.rho


def test_rho_lower_bound_is_deflated_and_deterministic():
    c = di_constants()
    a, b = rho_lower_bound(c, 1), rho_lower_bound(c, 1)
    assert a == b and LOWER_DEFLATE < 1.0 and math.isfinite(a)


@pytest.mark.slow
def test_cart_pole_designs_only_the_candidate_that_can_win(monkeypatch):
    calls = []
    real = l1system.design

    def counting(c, req):
        calls.append(float(c.lam))
        return real(c, req)

    monkeypatch.setattr(l1system, "design", counting)
    cert = certify(CART_POLE)
    # in x the cart-pole does not contract (no design); two metric candidates in z: the one with
    # cond P <= 100 is designed first (smaller bound) and certifies rho = 4.22 in x; the
    # rate-maximising one has rho_TaSIL = 2.88 and rho_L1 >= 2.2 for any design: skipped
    assert cert.certified and cert.coordinates is not None
    assert len(calls) == 1
    skipped = [a for a in cert.alternatives if a["verdict"] == "skipped"]
    assert len(skipped) == 1
    s = skipped[0]
    assert s["rho_l1_x"] is None and s["rho_tasil_x"] + s["rho_l1_x_at_least"] > (
        cert.rho_tasil + cert.rho_l1
    )
    json.dumps(cert.to_dict())  # the summary is JSON


def test_skip_rule_chooses_what_finishing_every_candidate_chooses(monkeypatch):
    """Random keys with random lower bounds (ties included): the candidate chosen among those
    finished is the one ``min`` chooses among all, in pool order, and only candidates whose
    bound rules them out are skipped."""
    from types import SimpleNamespace

    import drip_cert.bounds.certificate as C

    rng = np.random.default_rng(7)
    monkeypatch.setattr(C, "_finish", lambda u: u.cert)
    monkeypatch.setattr(C, "_preference", lambda cert: cert.key)
    monkeypatch.setattr(C, "_skipped_summary", lambda u, low, best: {"skipped": u.cert})
    skipped_any = False
    for _ in range(300):
        n_head, n = int(rng.integers(0, 2)), int(rng.integers(1, 5))
        keys = [
            (int(rng.integers(0, 2)), int(rng.integers(0, 2)), float(rng.integers(0, 3)))
            for _ in range(n_head + n)
        ]
        head = [SimpleNamespace(key=k) for k in keys[:n_head]]
        cands = []
        for k in keys[n_head:]:
            low = (k[0], k[1], k[2] - float(rng.integers(0, 2)))  # <= the key, ties often
            u = SimpleNamespace(
                cert=SimpleNamespace(key=k),
                l1=SimpleNamespace(designs=True),
                change=None,
                key_lower_bound=lambda low=low: low,
            )
            cands.append(u)
        out = C._finish_candidates(head, cands, lambda *a: None)
        pool = [*head, *(c for c in out if not isinstance(c, dict))]
        chosen = min(pool, key=lambda c: c.key)
        full = min([*head, *(u.cert for u in cands)], key=lambda c: c.key)
        assert chosen is full
        skipped_any |= any(isinstance(c, dict) for c in out)
    assert skipped_any
