"""The branch and bound of ``sup ||pi_IL - pi*||`` encloses its sub-boxes in batches.

Count of work: the networks are propagated once per round of sub-boxes (numerics/bnb.py doubles
the round up to ``SUP_DIFF_BATCH``), not once per sub-box; the bound still covers every sampled
value of ``||pi_IL(x) - pi*(x)||`` on the box and on the box cut by a ball.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import drip_cert.analysis.contraction.learned_loop as ll
from drip_cert.learn.imitation import learned_system
from drip_cert.model.mlp import MLP
from drip_cert.spec import load_spec
from tests.helpers import write_spec
from tests.test_learned_loop import SPEC4

#: sub-box budget of these searches (small: the test stays fast)
BOXES = 300
#: sampled points per check (a sampled max is a lower bound of the sup)
N_SAMPLES = 4000


@pytest.fixture(scope="module")
def system(tmp_path_factory):
    rng = np.random.default_rng(4)
    w1, w2 = 0.1 * rng.standard_normal((16, 4)), 0.5 * rng.standard_normal((4, 16))
    net = MLP(weights=(w1, w2), biases=(np.zeros(16), np.zeros(4)))
    base = load_spec(write_spec(tmp_path_factory.mktemp("sb"), SPEC4)).system
    return learned_system(base, net, linear=-np.eye(4) - w2 @ w1)


def _gap(s, X: np.ndarray) -> np.ndarray:
    pil = np.asarray([s.numeric.learned(x) for x in X])
    pst = np.asarray([s.numeric.expert(x) for x in X])
    return np.linalg.norm(pil - pst, axis=1)


@pytest.mark.parametrize("ball", [None, (np.array([0.3, -0.2, 0.1, 0.0]), 0.8)])
def test_sub_boxes_are_enclosed_in_batches_and_the_bound_holds(system, monkeypatch, ball):
    calls: list[int] = []
    real = ll.enclose_jacobian_centred

    def counting(mlp, lo, hi):
        calls.append(int(np.prod(np.shape(lo)[:-1])))
        return real(mlp, lo, hi)

    monkeypatch.setattr(ll, "enclose_jacobian_centred", counting)
    monkeypatch.setattr(ll, "SUP_DIFF_MAX_BOXES", BOXES)
    box = np.array([[-1.0, 1.0]] * 4)
    q = ll.sup_policy_difference(system, box, ball)
    assert q is not None
    n_boxes = int(re.search(r"(\d+) boxes", q.note).group(1))
    # every sub-box bounded exactly once, by one propagation per round of the search
    assert sum(calls) == n_boxes
    assert max(calls) > 1 and len(calls) * 4 <= n_boxes
    # the bound covers the sampled values on the set (box, or box cut by the ball)
    rng = np.random.default_rng(7)
    X = rng.uniform(-1.0, 1.0, (N_SAMPLES, 4))
    if ball is not None:
        X = X[np.linalg.norm(X - ball[0], axis=1) <= ball[1]]
        assert len(X) > 100
    assert float(np.max(_gap(system, X))) <= q.value
