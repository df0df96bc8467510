"""Linear models and gain experts in a spec: ``[dynamics] A, B``, ``expert = { K = ... }`` and
``expert = "lqr"`` with ``[policy.lqr] Q, R``. A, B give exactly the System of the equivalent
expressions; K gives u = -K x; the LQR gain is scipy's, taken exactly, with a Hurwitz closed loop
and the closed form of the double integrator; every bad value is a SpecError naming the key."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import sympy as sp

from drip_cert.errors import SpecError
from drip_cert.model.mlp import init_mlp
from drip_cert.spec import load_spec
from tests.helpers import CLOSED_FORM_TOL, example_spec, run_cli, write_spec

HEAD = """
[system]
name = "lin"
states = ["x1", "x2"]
horizon = 5.0
"""
TAIL = """
[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
"""
LINEAR = "[dynamics]\nA = [[0, 1], [-2, -0.3]]\nB = [[0], [1]]\n"
EXPRESSIONS = '[dynamics]\nf = ["x2", "-2*x1 - 0.3*x2"]\ng = [["0"], ["1"]]\n'
LQR = '[policy]\nexpert = "lqr"\n[policy.lqr]\nQ = [[1, 0], [0, 1]]\nR = [[1]]\n'
DOUBLE_INTEGRATOR = "[dynamics]\nA = [[0, 1], [0, 0]]\nB = [[0], [1]]\n"


def spec_text(dynamics: str = LINEAR, policy: str = LQR) -> str:
    return HEAD + dynamics + policy + TAIL


def load(tmp_path, text: str):
    return load_spec(write_spec(tmp_path, text))


def expressions_policy(expert: str) -> str:
    return f'[policy]\nexpert = ["{expert}"]\n'


# ------------------------------------------------------------------------------ A, B and K
def test_linear_model_is_the_system_of_the_equivalent_expressions(tmp_path):
    policy = expressions_policy("-x1 - x2")
    a = load(tmp_path, spec_text(LINEAR, policy)).system
    b = load(tmp_path, spec_text(EXPRESSIONS, policy)).system
    assert a.f == b.f and a.g == b.g  # exactly: the same sympy expressions
    x1, x2 = a.states
    assert list(a.f) == [x2, -2 * x1 - sp.Rational(3, 10) * x2]  # 0.3 is 3/10, not a float
    assert a.closed_loop_jacobian() == b.closed_loop_jacobian()


def test_linear_model_takes_a_known_diffusion(tmp_path):
    dyn = LINEAR + 'diffusion = [["0.01"], ["0.02"]]\n'
    s = load(tmp_path, spec_text(dyn, expressions_policy("-x1"))).system
    assert s.d == 1 and s.diffusion == sp.ImmutableMatrix(
        [[sp.Rational(1, 100)], [sp.Rational(1, 50)]]
    )


def test_toml_floats_are_the_rationals_of_their_text(tmp_path):
    # tomllib gives doubles; the loader keeps each float's text, so every digit written counts
    dyn = "[dynamics]\nA = [[0, 1], [-2, -0.6546960439030461848070769]]\nB = [[0], [1_0.5e-1]]\n"
    s = load(tmp_path, spec_text(dyn, expressions_policy("-x1"))).system
    x1, x2 = s.states
    assert list(s.f) == [x2, -2 * x1 - sp.Rational(6546960439030461848070769, 10**25) * x2]
    assert s.g[1, 0] == sp.Rational(105, 100)


def test_gain_expert_is_minus_K_x(tmp_path):
    policy = "[policy]\nexpert = { K = [[2, 0.5]] }\n"
    spec = load(tmp_path, spec_text(LINEAR, policy))
    x1, x2 = spec.system.states
    assert list(spec.system.expert) == [-2 * x1 - sp.Rational(1, 2) * x2]
    same = load(tmp_path, spec_text(LINEAR, expressions_policy("-2*x1 - 0.5*x2"))).system
    assert spec.system.expert == same.expert
    gain = spec.expert_gain
    assert gain.source == "K" and gain.K == sp.ImmutableMatrix([[2, sp.Rational(1, 2)]])
    acl = np.array([[0.0, 1.0], [-4.0, -0.8]])  # A - B K
    assert np.allclose(
        sorted(gain.closed_loop_eigenvalues, key=lambda z: (z.real, z.imag)),
        sorted(np.linalg.eigvals(acl), key=lambda z: (z.real, z.imag)),
        rtol=0,
        atol=CLOSED_FORM_TOL,
    )
    # the same gain written as a table [policy.expert]
    table = load(tmp_path, spec_text(LINEAR, "[policy.expert]\nK = [[2, 0.5]]\n"))
    assert table.system.expert == spec.system.expert


def test_gain_expert_on_a_nonlinear_model_keeps_f(tmp_path):
    dyn = '[dynamics]\nf = ["x2", "-sin(x1) - x2**3"]\ng = [["0"], ["1"]]\n'
    spec = load(tmp_path, spec_text(dyn, "[policy]\nexpert = { K = [[1, 2]] }\n"))
    x1, x2 = spec.system.states
    assert list(spec.system.f) == [x2, -sp.sin(x1) - x2**3]
    assert list(spec.system.expert) == [-x1 - 2 * x2]
    assert spec.expert_gain.linearised  # poles of the linearisation [[0, 1], [-2, -2]]
    assert all(z.real < 0 for z in spec.expert_gain.closed_loop_eigenvalues)


# ------------------------------------------------------------------------------------- LQR
def _scipy_lqr(A, B, Q, R):
    P = scipy.linalg.solve_continuous_are(A, B, Q, R)
    return np.linalg.solve(R, B.T @ P)


def test_lqr_gain_is_scipys_taken_exactly_and_the_closed_loop_is_hurwitz(tmp_path):
    dyn = "[dynamics]\nA = [[0, 1, 0], [0, 0, 1], [1, -2, 0.5]]\nB = [[0, 0], [1, 0], [0, 1]]\n"
    pol = '[policy]\nexpert = "lqr"\n[policy.lqr]\nQ = [[2, 0, 0], [0, 1, 0.5], [0, 0.5, 1]]\n'
    pol += "R = [[1, 0.2], [0.2, 3]]\n"
    text = (HEAD + dyn + pol + TAIL).replace('["x1", "x2"]', '["x1", "x2", "x3"]')
    text = text.replace("[[-1.0, 1.0], [-1.0, 1.0]]", "[[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]]")
    spec = load(tmp_path, text)
    A = np.array([[0, 1, 0], [0, 0, 1], [1, -2, 0.5]], dtype=float)
    B = np.array([[0, 0], [1, 0], [0, 1]], dtype=float)
    Q = np.array([[2, 0, 0], [0, 1, 0.5], [0, 0.5, 1]], dtype=float)
    R = np.array([[1, 0.2], [0.2, 3]])
    K = _scipy_lqr(A, B, Q, R)
    gain = spec.expert_gain
    assert gain.source == "lqr" and not gain.linearised
    assert np.array_equal(gain.K_float, K)  # the same LAPACK calls: the same floats
    # the expert is exactly -K x with the rationals of those floats
    x = sp.Matrix(spec.system.states)
    Kx = sp.Matrix([[sp.Rational(float(k)) for k in row] for row in K])
    assert spec.system.expert == sp.ImmutableMatrix(-Kx * x)
    eigs = np.linalg.eigvals(A - B @ K)
    assert max(eigs.real) < 0
    assert max(z.real for z in gain.closed_loop_eigenvalues) == pytest.approx(
        max(eigs.real), abs=CLOSED_FORM_TOL
    )
    assert "LQR" in spec.notes[0] and "R = [[1.0, 0.2], [0.2, 3.0]]" in spec.notes[0]


def test_lqr_double_integrator_closed_form(tmp_path):
    """Q = I, R = 1 on q'' = u: P = [[sqrt(3), 1], [1, sqrt(3)]], K = [1, sqrt(3)]."""
    spec = load(tmp_path, spec_text(DOUBLE_INTEGRATOR, LQR))
    K = spec.expert_gain.K_float
    assert np.allclose(K, [[1.0, np.sqrt(3.0)]], rtol=0, atol=CLOSED_FORM_TOL)
    # closed loop s^2 + sqrt(3) s + 1: poles -sqrt(3)/2 +- i/2
    poles = spec.expert_gain.closed_loop_eigenvalues
    assert np.allclose(
        [(z.real, abs(z.imag)) for z in poles],
        [(-np.sqrt(3) / 2, 0.5)] * 2,
        rtol=0,
        atol=CLOSED_FORM_TOL,
    )
    x1, x2 = spec.system.states
    assert spec.system.closed_loop()[0] == x2
    assert spec.expert_gain.to_dict()["source"] == "lqr"


def test_lqr_on_a_nonlinear_model_uses_the_linearisation_at_the_origin(tmp_path):
    dyn = '[dynamics]\nf = ["x2", "-sin(x1) - 0.5*x2 + x1**2*x2"]\ng = [["0"], ["1"]]\n'
    spec = load(tmp_path, spec_text(dyn, LQR))
    A = np.array([[0.0, 1.0], [-1.0, -0.5]])  # df/dx at 0
    B = np.array([[0.0], [1.0]])
    K = _scipy_lqr(A, B, np.eye(2), np.eye(1))
    assert np.array_equal(spec.expert_gain.K_float, K)
    assert spec.expert_gain.linearised
    assert "linearisation at x = 0" in spec.notes[0]
    x1, _ = spec.system.states
    assert spec.system.f[1].has(sp.sin(x1))  # the model itself stays nonlinear


# ----------------------------------------------------------------------------- bad inputs
BAD = [
    # (dynamics, policy, field, fragment)
    (LINEAR + 'f = ["x2", "-x1"]\n', LQR, "dynamics.A", "not both"),
    ("[dynamics]\nA = [[0, 1], [0, 0]]\n", LQR, "dynamics.B", "missing key"),
    ('[dynamics]\ng = [["0"], ["1"]]\n', LQR, "dynamics.f", "missing key"),
    ("[dynamics]\nA = [[0, 1], [0, 0], [1, 1]]\nB = [[0], [1]]\n", LQR, "dynamics.A", "2 x 2"),
    ("[dynamics]\nA = [[0, 1], [0]]\nB = [[0], [1]]\n", LQR, "dynamics.A", "row 1 has 1"),
    ("[dynamics]\nA = [[0, 1, 2], [0, 0, 1]]\nB = [[0], [1]]\n", LQR, "dynamics.A", "not 2"),
    ('[dynamics]\nA = [[0, "x1"], [0, 0]]\nB = [[0], [1]]\n', LQR, "dynamics.A[0][1]", '"x1"'),
    ("[dynamics]\nA = [[0, true], [0, 0]]\nB = [[0], [1]]\n", LQR, "dynamics.A[0][1]", "number"),
    ("[dynamics]\nA = [[0, nan], [0, 0]]\nB = [[0], [1]]\n", LQR, "dynamics.A[0][1]", "finite"),
    ("[dynamics]\nA = [[0, 1], [0, 0]]\nB = [0, 1]\n", LQR, "dynamics.B", "list of rows"),
    ("[dynamics]\nA = [[0, 1], [0, 0]]\nB = [[1]]\n", LQR, "dynamics.B", "not 2"),
    (LINEAR, "[policy]\nexpert = { K = [[1, 2, 3]] }\n", "policy.expert.K", "1 x 2"),
    (LINEAR, "[policy]\nexpert = { K = [[1], [2]] }\n", "policy.expert.K", "1 x 2"),
    (LINEAR, '[policy]\nexpert = { K = [[1, "k"]] }\n', "policy.expert.K[0][1]", "number"),
    (LINEAR, "[policy]\nexpert = { G = [[1, 2]] }\n", "policy.expert.G", "unknown key"),
    (LINEAR, "[policy]\nexpert = {}\n", "policy.expert.K", "no gain"),
    (LINEAR, '[policy]\nexpert = "lq"\n', "policy.expert", '"lqr"'),
    (LINEAR, "[policy]\nexpert = 3\n", "policy.expert", "not allowed"),
    (LINEAR, '[policy]\nexpert = "lqr"\n', "policy.lqr", "needs the table"),
    (
        LINEAR,
        '[policy]\nexpert = ["-x1"]\n[policy.lqr]\nQ = [[1, 0], [0, 1]]\nR = [[1]]\n',
        "policy.lqr",
        'write expert = "lqr"',
    ),
    (
        LINEAR,
        LQR.replace("Q = [[1, 0], [0, 1]]", "Q = [[1, 0, 0], [0, 1, 0]]"),
        "policy.lqr.Q",
        "2 x 2",
    ),
    (
        LINEAR,
        LQR.replace("Q = [[1, 0], [0, 1]]", "Q = [[1, 0.5], [0, 1]]"),
        "policy.lqr.Q",
        "symmetric",
    ),
    (
        LINEAR,
        LQR.replace("Q = [[1, 0], [0, 1]]", "Q = [[1, 0], [0, -1]]"),
        "policy.lqr.Q",
        "semidefinite",
    ),
    (
        LINEAR,
        LQR.replace("Q = [[1, 0], [0, 1]]", 'Q = [[1, 0], [0, "a"]]'),
        "policy.lqr.Q[1][1]",
        "number",
    ),
    (LINEAR, LQR.replace("R = [[1]]", "R = [[0]]"), "policy.lqr.R", "positive definite"),
    (LINEAR, LQR.replace("R = [[1]]", "R = [[-2.5]]"), "policy.lqr.R", "R = [[-2.5]]"),
    (LINEAR, LQR.replace("R = [[1]]", "R = [[1, 0], [0, 1]]"), "policy.lqr.R", "1 x 1"),
    (LINEAR, LQR.replace("R = [[1]]", "R = [[1]]\nS = 3"), "policy.lqr.S", "unknown key"),
    (LINEAR, LQR.replace("R = [[1]]", "R = [[1]]\nQs = 3"), "policy.lqr.Qs", "Did you mean Q"),
    (LINEAR, LQR.replace("Q = [[1, 0], [0, 1]]\n", ""), "policy.lqr.Q", "missing key Q"),
    (
        "[dynamics]\nA = [[1, 0], [0, -1]]\nB = [[0], [1]]\n",
        LQR,
        "policy.expert",
        "not stabilisable",
    ),
    (
        DOUBLE_INTEGRATOR,
        LQR.replace("Q = [[1, 0], [0, 1]]", "Q = [[0, 0], [0, 0]]"),
        "policy.lqr.Q",
        "unobservable",
    ),
    (
        "[dynamics]\nA = [[0, 1], [-2, -3e-2000]]\nB = [[0], [1]]\n",
        LQR,
        "dynamics.A[1][1]",
        "'-3e-2000' has a decimal exponent beyond",
    ),
    ('[dynamics]\nf = ["x2", "1 - x1"]\ng = [["0"], ["1"]]\n', LQR, "policy.expert", "f(0) = "),
    (
        '[dynamics]\nf = ["x2", "-x1 + t*x2"]\ng = [["0"], ["1"]]\n',
        LQR,
        "policy.expert",
        "time-invariant",
    ),
]


@pytest.mark.parametrize("dynamics, policy, field, fragment", BAD)
def test_bad_linear_specs_raise_spec_error_naming_the_key(
    tmp_path, dynamics, policy, field, fragment
):
    path = write_spec(tmp_path, spec_text(dynamics, policy))
    with pytest.raises(SpecError) as info:
        load_spec(path)
    msg = str(info.value)
    assert str(path) in msg
    assert info.value.field == field, msg
    assert fragment in msg


def test_lqr_on_a_block_model_says_to_give_K(tmp_path):
    init_mlp([2, 3, 1], np.random.default_rng(0)).save(tmp_path / "h.npz")
    blk = '[blocks.h]\nkind = "mlp"\nweights = "h.npz"\ninputs = 2\noutputs = 1\n'
    dyn = '[dynamics]\nf = ["x2", "-x1 + h(x)[0]"]\ng = [["0"], ["1"]]\n'
    text = HEAD + blk + dyn + LQR + TAIL
    with pytest.raises(SpecError, match=r"block\(s\)") as info:
        load(tmp_path, text)
    assert info.value.field == "policy.expert" and "expert = { K" in str(info.value)


def test_check_spec_exit_2_on_a_bad_R(tmp_path, capsys):
    path = write_spec(
        tmp_path, spec_text(LINEAR, LQR.replace("R = [[1]]", "R = [[0]]")), "bad.toml"
    )
    code, out, err = run_cli(capsys, "check-spec", str(path))
    assert code == 2 and out == ""
    assert str(path) in err and "policy.lqr.R" in err and "positive definite" in err
    assert "Traceback" not in err


# -------------------------------------------------------------------------------- examples
def test_the_three_natural_coordinate_examples_load():
    pend = load_spec(example_spec("pendulum"))
    vdp = load_spec(example_spec("van_der_pol"))
    cart = load_spec(example_spec("cart_pole"))
    for spec, n in ((pend, 2), (vdp, 2), (cart, 4)):
        assert spec.system.n == n and spec.system.m == 1
        assert spec.settings.l1drac is not None
    q, q_dot = pend.system.states
    # gravity compensation: the expert closed loop is linear, q'' = -4 q - 4.5 q'
    assert list(pend.system.closed_loop()) == [q_dot, -4 * q - sp.Rational(9, 2) * q_dot]
    gain = cart.expert_gain
    assert gain.source == "lqr" and not gain.linearised
    assert max(z.real for z in gain.closed_loop_eigenvalues) < 0
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [0, -0.981, 0, 0], [0, 21.582, 0, 0]], dtype=float)
    B = np.array([[0.0], [0.0], [1.0], [-2.0]])
    K = _scipy_lqr(A, B, np.diag([1.0, 10.0, 1.0, 1.0]), np.array([[0.1]]))
    assert np.array_equal(gain.K_float, K)


def test_check_spec_and_certify_report_where_the_lqr_gain_came_from(capsys):
    """The gain of an ``expert = "lqr"`` spec is printed by check-spec (text and JSON) and kept
    among the certificate's notes (also when the certificate is computed in z = Theta x)."""
    import json

    from drip_cert.bounds.certificate import certify

    path = example_spec("cart_pole")
    code, out, _ = run_cli(capsys, "check-spec", str(path))
    assert code == 0 and "from LQR (scipy.linalg.solve_continuous_are)" in out
    code, out, _ = run_cli(capsys, "check-spec", str(path), "--json")
    assert code == 0 and "closed-loop eigenvalues" in json.loads(out)["notes"][0]
    cert = certify(load_spec(path))
    assert cert.coordinates is not None
    assert any("from LQR" in n for n in cert.notes)
