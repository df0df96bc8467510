"""The fast (24) oracle of the search over rho_a computes the same two floats as the generic
sides of (24) (:func:`~drip_cert.bounds.l1drac.sides.sides_24_at`), bit for bit, so every search
and design built on it is the same number as before it existed."""

from __future__ import annotations

import numpy as np
import pytest

import drip_cert.bounds.l1drac.searches as searches
from drip_cert.bounds.l1drac.appendix import sampling_constants, true_constants
from drip_cert.bounds.l1drac.conditions import holds_24_at, sides_24_oracle
from drip_cert.bounds.l1drac.sides import sides_24_at
from tests.helpers import di_constants, random_constants

#: (omega, lambda_s, Ts) in multiples of (lambda, lambda, 1/lambda): omega below and above
#: 2 lambda, lambda_s below and above omega, Ts from 1e-6 to 1e-2 of 1/lambda
POINTS = (
    (0.01, 0.1, 1e-4),
    (0.5, 3.0, 1e-3),
    (5.0, 50.0, 1e-5),
    (100.0, 1e3, 1e-6),
    (3.0, 1.0, 1e-2),
)
#: random rho_a per point: log-uniform over 24 decades, where the searches' bisections go
N_Y = 200


def _constants(seed):
    return random_constants(np.random.default_rng(seed)) if seed else di_constants()


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("p", [1, 2])
@pytest.mark.parametrize("envelope", [False, True])
def test_sides_are_the_same_floats(seed, p, envelope):
    c = _constants(seed)
    tc = true_constants(c, p)
    lam = float(c.lam)
    rng = np.random.default_rng(100 + seed)
    for kw, kl, kt in POINTS:
        w, ls, Ts = kw * lam, kl * lam, kt / lam
        s = sampling_constants(c, p, w, Ts, ls, envelope=envelope)
        for rho_r in (0.0, 1.5, float(10.0 ** rng.uniform(-6, 6))):
            fast = sides_24_oracle(c, tc, s, w, rho_r)
            assert fast.__name__ == "sides"  # the float path, not the generic fallback
            for y in 10.0 ** rng.uniform(-12, 12, N_Y):
                assert fast(float(y)) == sides_24_at(c, tc, s, w, rho_r, float(y))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_search_of_rho_a_is_the_same_number(seed, monkeypatch):
    c = _constants(seed)
    p = 1
    tc = true_constants(c, p)
    lam = float(c.lam)
    found = []
    for kw, kl, kt in POINTS:
        w, ls, Ts = kw * lam, kl * lam, kt / lam
        found.append(searches.min_rho_a(c, tc, p, w, 1.5, ls, Ts, ("16b", "21b", "24")))
    with monkeypatch.context() as m:
        m.setattr(
            searches,
            "sides_24_oracle",
            lambda c, tc, s, w, r: lambda y: sides_24_at(c, tc, s, w, r, y),
        )
        generic = [
            searches.min_rho_a(c, tc, p, kw * lam, 1.5, kl * lam, kt / lam, ("16b", "21b", "24"))
            for kw, kl, kt in POINTS
        ]
    assert found == generic  # bit for bit (None where no rho_a exists)
    assert any(r is not None for r in found)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_oracles_are_the_results_holds(seed):
    """The searches ask ``holds_of(eq, *sides)`` and the compare form of the (24) oracle: the
    ``holds`` of the full condition results, without building them."""
    from drip_cert.bounds.l1drac.appendix import reference_constants
    from drip_cert.bounds.l1drac.conditions import (
        float_16a,
        float_16b,
        float_21a,
        float_21b,
        holds_24_oracle,
        holds_of,
        holds_r_oracle,
        sides_r_oracle,
    )
    from drip_cert.bounds.l1drac.sides import sides_16a, sides_16b, sides_21a, sides_21b

    c = _constants(seed)
    p = 1
    rc, tc = reference_constants(c, p), true_constants(c, p)
    lam = float(c.lam)
    rng = np.random.default_rng(200 + seed)
    for kw, kl, kt in POINTS:
        w, ls, Ts = kw * lam, kl * lam, kt / lam
        s = sampling_constants(c, p, w, Ts, ls)
        oracle = holds_24_oracle(c, tc, s, w, 1.5)
        o16a, o21a = holds_r_oracle(c, rc, w, "16a"), holds_r_oracle(c, rc, w, "21a")
        assert o16a.__name__ == "holds_16a" and o21a.__name__ == "holds_21a"  # the float path
        s16a, s21a = sides_r_oracle(c, rc, w, "16a"), sides_r_oracle(c, rc, w, "21a")
        assert s16a.__name__ == "sides_16a" and s21a.__name__ == "sides_21a"
        for x in 10.0 ** rng.uniform(-6, 6, N_Y):
            x = float(x)
            assert holds_of("16a", *sides_16a(c, rc, w, x)) == float_16a(c, rc, w, x).holds
            assert holds_of("21a", *sides_21a(c, rc, w, x)) == float_21a(c, rc, w, x).holds
            assert holds_of("16b", *sides_16b(c, tc, w, x)) == float_16b(c, tc, w, x).holds
            want_21b = float_21b(c, tc, w, 1.5, x).holds
            assert holds_of("21b", *sides_21b(c, tc, w, 1.5, x)) == want_21b
            assert oracle(x) == holds_24_at(c, tc, s, w, 1.5, x)
            assert o16a(x) == float_16a(c, rc, w, x).holds
            assert o21a(x) == float_21a(c, rc, w, x).holds
            assert s16a(x) == sides_16a(c, rc, w, x)  # the searches' floats, bit for bit
            assert s21a(x) == sides_21a(c, rc, w, x)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_search_of_rho_r_is_the_same_number(seed, monkeypatch):
    from drip_cert.bounds.l1drac.appendix import reference_constants
    from drip_cert.bounds.l1drac.sides import sides_16a, sides_21a

    c = _constants(seed)
    rc = reference_constants(c, 1)
    lam = float(c.lam)
    omegas = [k * lam for k in (0.01, 0.5, 1.5, 3.0, 50.0)]
    found = [searches.min_rho_r(c, rc, w, ("16a", "21a")) for w in omegas]
    side = {"16a": sides_16a, "21a": sides_21a}
    with monkeypatch.context() as m:
        m.setattr(searches, "sides_r_oracle", lambda c, rc, w, eq: lambda x: side[eq](c, rc, w, x))
        generic = [searches.min_rho_r(c, rc, w, ("16a", "21a")) for w in omegas]
    assert found == generic  # bit for bit (None where no rho_r exists)
    assert any(r is not None for r in found)
