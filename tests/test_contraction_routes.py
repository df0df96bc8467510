"""The routes of the contraction rate: named once (:mod:`drip_cert.vocabulary`), implemented
once (:data:`drip_cert.analysis.contraction.rate.ROUTES`), offered by the settings under those
names.

The mathematics: ``J = diag(-1 - x1^2, -2)`` on ``x1 in [-1, 1]`` has
``mu_2(J) = max(-1 - x1^2, -2) = -1 - x1^2``, largest (``-1``) at ``x1 = 0``: the rate is 1.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

from drip_cert.analysis.contraction.rate import ROUTES, SamplingOptions, contraction_rate
from drip_cert.errors import SpecError
from drip_cert.provenance import How
from drip_cert.spec.settings import ContractionSettings
from drip_cert.vocabulary import CONTRACTION_AUTO, CONTRACTION_METHODS, CONTRACTION_ROUTES

TOL = 1e-3  # requested gap of the branch and bound (the route's own target)
RATE = 1.0  # the closed-form rate of the example (module docstring)
ROUND = 1e-12  # the exact route's rate is the outward-rounded lower end of an Arb enclosure
SAMPLING = SamplingOptions(n_grid=65, n_random=16, n_local=1, seed=0)  # small: the centre is on it


def test_settings_offer_exactly_the_registered_routes():
    method = next(f for f in dataclasses.fields(ContractionSettings) if f.name == "method")
    choices = method.metadata["args"][0]
    assert choices == (CONTRACTION_AUTO, *ROUTES)
    assert tuple(ROUTES) == tuple(name for name, _ in CONTRACTION_ROUTES)
    assert CONTRACTION_METHODS == choices


def test_every_route_has_a_one_line_meaning():
    for name, meaning in CONTRACTION_ROUTES:
        assert meaning and "\n" not in meaning, name


def test_a_spec_may_name_every_registered_route():
    """``mlp-bnb`` was implemented in analysis but refused by the settings."""
    for name in CONTRACTION_METHODS:
        assert ContractionSettings(method=name).method == name
    with pytest.raises(SpecError, match="method"):
        ContractionSettings(method="bnb")


def _example():
    x1, x2 = sp.symbols("x1 x2")
    J = sp.Matrix([[-1 - x1**2, 0], [0, -2]])
    return J, [x1, x2], np.array([[-1.0, 1.0], [-1.0, 1.0]])


@pytest.mark.parametrize("name", ["interval-bnb", "sampled"])
def test_a_named_route_runs_that_route_and_finds_the_closed_form_rate(name):
    J, states, box = _example()
    r = contraction_rate(J, states, box, method=name, tol=TOL, sampling=SAMPLING)
    assert r.method == name
    if r.how == How.SOUND:
        assert RATE - TOL <= r.rate <= RATE  # a sound bound: below the true rate, within tol
    else:
        assert r.how == How.ESTIMATE
        assert r.rate == pytest.approx(RATE, abs=1e-12)  # x1 = 0 is on the grid


def test_auto_takes_the_first_route_that_applies():
    J, states, box = _example()
    assert contraction_rate(J, states, box, tol=TOL, sampling=SAMPLING).method == "interval-bnb"
    const = contraction_rate(sp.Matrix([[-1, 0], [0, -2]]), states, method="sampled")
    assert const.method == "exact-linear"  # a constant J: always the closed form
    assert RATE - ROUND <= const.rate <= RATE
    with pytest.raises(SpecError, match="exact-linear"):
        contraction_rate(J, states, box, method="exact-linear")
    with pytest.raises(SpecError, match="mlp-bnb"):
        contraction_rate(J, states, box, method="mlp-bnb")
