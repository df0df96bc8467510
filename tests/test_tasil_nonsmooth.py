"""TaSIL for a policy whose Jacobian is not Lipschitz (relu): the sound continuous-time h0 from a
Lipschitz constant of Delta alone, and the held-out form through the comparison bound (docs/math/
tasil.md 3.3 c and 3.7) that needs neither h1 nor a Jacobian-Lipschitz constant."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drip_cert.bounds.tasil._common import up_closed_form
from drip_cert.bounds.tasil.forms import form_held_out_comparison
from drip_cert.bounds.tasil.trajectory import h0_lipschitz
from drip_cert.errors import SpecError
from drip_cert.numerics.stats import clopper_pearson_upper

DENSE_TOL = 1e-12  # dense-grid sup vs the sound bound: float evaluation of the same norms
GRID_REFINED_REL = 0.05  # a 100x finer grid brings the bound within O(dt) of the true sup
DECAY = 0.1  # x(t) = e^{-DECAY t} (cos t, sin t): speed e^{-DECAY t} sqrt(1 + DECAY^2)


def _spiral(t):
    r = np.exp(-DECAY * t)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


def _speed(t):
    """sup ||x_dot|| on each [t_i, t_{i+1}]: the speed decreases, so its left value."""
    return np.exp(-DECAY * t[:-1]) * math.sqrt(1.0 + DECAY**2)


def _relu_delta(x, w, b, c):
    """A piecewise-linear error, Lipschitz with constant sum_k |c_k| ||w_k||."""
    return (np.maximum(x @ w.T + b, 0.0) @ c)[:, None]


def test_h0_from_a_lipschitz_constant_dominates_the_dense_sup_of_a_relu_error():
    rng = np.random.default_rng(3)
    for _ in range(5):
        w, b, c = rng.normal(size=(6, 2)), rng.normal(size=6) * 0.3, rng.normal(size=6)
        lip = float(np.sum(np.abs(c) * np.linalg.norm(w, axis=1)))
        t = np.linspace(0.0, 6.0, 25)
        h0 = h0_lipschitz(t, _relu_delta(_spiral(t), w, b, c), _speed(t), lip)
        td = np.linspace(0.0, 6.0, 60_001)
        dense = float(np.max(np.abs(_relu_delta(_spiral(td), w, b, c))))
        assert h0 >= dense - DENSE_TOL
        t2 = np.linspace(0.0, 6.0, 2401)
        fine = h0_lipschitz(t2, _relu_delta(_spiral(t2), w, b, c), _speed(t2), lip)
        assert dense - DENSE_TOL <= fine <= dense + GRID_REFINED_REL * max(1.0, dense)
        assert fine <= h0 + DENSE_TOL
    with pytest.raises(SpecError, match="too small"):  # a constant the data contradict
        h0_lipschitz(t, _relu_delta(_spiral(t), w, b, c), _speed(t), 1e-6 * lip)


def test_held_out_form_through_the_comparison_bound():
    delta, cg, tau0 = 0.1, 2.0, 0.5
    n_val = 59  # the fewest held-out trajectories with which the form can pass at delta = 0.1
    h0v = np.linspace(0.0, tau0, n_val)  # none exceeds tau0 (the last equals it)
    f = form_held_out_comparison(h0v, tau0, cg, delta)
    eps = float(clopper_pearson_upper(0, n_val, alpha=delta / 2.0, sound=True))
    assert f.name == "held_out" and f.holds and not f.vacuous
    assert f.epsilon == eps <= delta / 2.0
    assert f.value == up_closed_form(cg * tau0) >= cg * tau0
    assert {c.id for c in f.checks} == {"tasil.held_out.level", "tasil.comparison"}
    assert "not applicable" in f.note and "comparison bound" in f.note
    # one exceedance spends more than the budget: the level check fails, the radius stays
    bad = form_held_out_comparison(np.append(h0v[:-1], 2 * tau0), tau0, cg, delta)
    assert not bad.holds and bad.value == f.value
    # too few held-out trajectories can never pass, and the note says how many are needed
    few = form_held_out_comparison(h0v[:20], tau0, cg, delta)
    assert not few.holds and "heldout >= 59" in few.note
