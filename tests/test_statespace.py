"""``System.from_statespace``: linear systems from objects with ``.A``/``.B`` (python-control,
scipy) or ``(A, B)`` arrays, with a gain expert ``u = -K x`` (issue 23)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import sympy as sp

from drip_cert import System
from drip_cert.errors import InputTypeError, SpecError
from drip_cert.model.mlp import init_mlp

A = np.array([[0.0, 1.0], [-1.0, -0.5]])
B = np.array([[0.0], [1.0]])
BOX = [[-1.0, 1.0], [-1.0, 1.0]]


class FakeStateSpace:
    """The duck type: what ``control.ss`` and ``scipy.signal.StateSpace`` have in common."""

    def __init__(self, A, B, dt=0, state_labels=None, input_labels=None):
        self.A, self.B, self.dt = A, B, dt
        if state_labels is not None:
            self.state_labels, self.input_labels = state_labels, input_labels


def _lqr_gain() -> np.ndarray:
    P = scipy.linalg.solve_continuous_are(A, B, np.eye(2), np.eye(1))
    return B.T @ P


def test_object_with_A_B_and_a_gain_give_f_Ax_g_B_and_the_exact_expert():
    K = _lqr_gain()
    s = System.from_statespace(FakeStateSpace(A, B), expert=K, support=BOX, horizon=2.0)
    x1, x2 = s.states
    assert [str(v) for v in s.states] == ["x1", "x2"] and s.inputs == ("u1",)
    assert s.f == sp.ImmutableMatrix([x2, -x1 - sp.Rational(1, 2) * x2])
    assert s.g == sp.ImmutableMatrix([[0], [1]])
    # u = -K x with the doubles of K taken exactly (the binary rational each stores)
    want = -(sp.Rational(float(K[0, 0])) * x1 + sp.Rational(float(K[0, 1])) * x2)
    assert sp.expand(s.expert[0] - want) == 0
    # the pair (A, B) gives the same system
    t = System.from_statespace((A, B), expert=K, support=BOX, horizon=2.0)
    assert (t.f, t.g, t.expert) == (s.f, s.g, s.expert)


def test_labels_expressions_and_a_network_as_policies():
    obj = FakeStateSpace(A, B, state_labels=["p", "v"], input_labels=["F"])
    net = init_mlp([2, 4, 1], np.random.default_rng(0))
    s = System.from_statespace(
        obj, expert=["-p - v"], learned=net, support=BOX, horizon=1.0, Delta_mu=0.1
    )
    p, v = s.states
    assert (str(p), str(v), s.inputs) == ("p", "v", ("F",))
    assert s.expert[0] == -p - v
    assert "pi_il" in s.blocks
    x = np.array([0.3, -0.2])
    got = float(np.asarray(s.numeric.learned(x))[0])
    assert got == pytest.approx(float(net.apply_np(x)[0]), rel=1e-12)


@pytest.mark.parametrize(
    "obj, kwargs, err, fragment",
    [
        (FakeStateSpace(A, B, dt=0.1), {}, SpecError, "discrete-time"),
        (object(), {}, InputTypeError, ".A and .B"),
        ((A, B), {"expert": np.ones((2, 2))}, SpecError, "m x n = 1 x 2"),
        ((A[:1], B), {}, SpecError, "square"),
        ((A, np.array([[np.inf], [1.0]])), {}, SpecError, "not finite"),
        ((A, B), {"states": ["a"]}, SpecError, "1 names for 2 states"),
    ],
)
def test_bad_inputs_say_what_is_wrong(obj, kwargs, err, fragment):
    args = {"expert": np.array([[1.0, 1.0]]), "support": BOX, "horizon": 1.0, **kwargs}
    with pytest.raises(err, match=fragment):
        System.from_statespace(obj, **args)


def test_python_control_ss_and_lqr():
    control = pytest.importorskip("control")
    sys = control.ss(A, B, np.eye(2), np.zeros((2, 1)), states=["p", "v"], inputs=["F"])
    K, _, _ = control.lqr(sys, np.eye(2), np.eye(1))
    s = System.from_statespace(sys, expert=K, support=BOX, horizon=2.0)
    assert [str(v) for v in s.states] == ["p", "v"] and s.inputs == ("F",)
    ref = System.from_statespace((A, B), expert=np.asarray(K), support=BOX, horizon=2.0)
    assert sp.expand(s.expert[0] - ref.expert[0].subs(dict(zip(ref.states, s.states)))) == 0
