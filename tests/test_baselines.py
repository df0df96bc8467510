"""DAgger and DART (drip_cert/learn/baselines.py): the label budget, DAgger's data (learner-visited
states labelled by the expert, checked against the closed-form solution of a linear loop), DART's
noise (applied as drawn, seeded, with the requested covariance, fitted to the learner's error),
determinism of the trained policies, and the ``train --method`` / ``--compare`` options."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy.linalg import expm

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.learn.baselines import (
    DIVERGENCE_FACTOR,
    dart_noise,
    error_covariance,
    split_budget,
    train_baseline,
)
from drip_cert.learn.data import Demonstrations, generate_demonstrations
from drip_cert.spec.settings import TRAIN_METHODS, TasilSettings
from tests.helpers import run_cli, two_state_spec, write_spec

# the linear test loop x1' = x2, x2' = -x1 - x2 + u: closed-form solutions by expm
A = np.array([[0.0, 1.0], [-1.0, -1.0]])
B = np.array([[0.0], [1.0]])
K_EXPERT = np.array([[-1.0, -2.0]])  # pi*(x) = -x1 - 2 x2
K_LEARNER = np.array([[-0.5, 0.0]])  # a deliberately poor learner: its states differ from pi*'s
BOX = np.array([[-1.0, 1.0], [-1.0, 1.0]])
T, K, N = 2.0, 20, 8

RK4_ATOL = 1e-9  # RK4, h = T/(K*8) = 0.0125 on a loop with |eigenvalues| <= 1.2: error ~ 1e-11
DART_RK4_ATOL = 1e-8  # the same RK4 with inputs of sd 0.3 held per interval: observed 1.7e-9
LABEL_ATOL = 1e-15  # expert labels: two products and a sum of O(1) floats, rounding only
DIFFERENT = 1e-3  # "not on an expert trajectory": the learner's states differ by at least this
COV_SAMPLES = 20000  # draws for the covariance check
COV_RTOL = 0.05  # std of a sample variance with 20000 draws ~ sqrt(2/20000) = 1 %: 5 sigma
SEED = 3


def field(t, x, u):
    return jnp.asarray(A) @ x + jnp.asarray(B) @ u


def expert(x):
    return jnp.asarray(K_EXPERT) @ x


def learner(x):
    return jnp.asarray(K_LEARNER) @ x


@pytest.fixture(scope="module")
def expert_demos() -> Demonstrations:
    return generate_demonstrations(field, expert, BOX, N, T, K, jax.random.PRNGKey(0))


class FakeFit:
    """A ``fit`` that records the data it was given and returns the fixed linear ``learner``."""

    def __init__(self) -> None:
        self.seen: list[tuple[int, int]] = []

    def __call__(self, data: Demonstrations, steps: int):
        self.seen.append((data.n_traj, steps))
        return None, learner


def closed_loop_states(Kp: np.ndarray, x0: np.ndarray, offsets: np.ndarray | None = None):
    """Exact samples of x' = (A + B Kp) x + B eta_j on [t_j, t_{j+1}) (eta = 0 when None)."""
    Acl = A + B @ Kp
    dt = T / K
    Phi = expm(Acl * dt)
    # int_0^dt e^{Acl s} ds B, from the augmented exponential
    M = np.zeros((3, 3))
    M[:2, :2], M[:2, 2:] = Acl, B
    Gam = expm(M * dt)[:2, 2:]
    xs = [x0]
    for j in range(K):
        eta = np.zeros(1) if offsets is None else offsets[j]
        xs.append(Phi @ xs[-1] + Gam @ eta)
    return np.array(xs)


def test_budget_split_sums_to_n_and_is_balanced():
    assert split_budget(20, 4) == (5, 5, 5, 5)
    assert split_budget(7, 3) == (3, 2, 2)
    assert split_budget(2, 4) == (1, 1)  # never more iterations than trajectories
    with pytest.raises(SpecError):
        split_budget(0, 4)


def test_dagger_aggregates_learner_states_labelled_by_the_expert(expert_demos):
    fit = FakeFit()
    run = train_baseline(
        "dagger", expert_demos, field, expert, BOX, fit, steps=40, seed=SEED, iterations=4
    )
    shares = split_budget(N, 4)
    # the same label budget as BC / TaSIL on expert_demos: N trajectories of K used samples
    assert run.data.n_traj == N and run.labels == N * K
    # learners trained on the growing aggregate, the last one with the full step budget
    assert fit.seen == [(2, 10), (4, 10), (6, 10), (8, 40)]
    # iteration 0 is the first expert trajectories, unchanged
    np.testing.assert_array_equal(run.data.states[: shares[0]], expert_demos.states[: shares[0]])
    for i in range(shares[0], N):
        x0 = run.data.x0[i]
        exact = closed_loop_states(K_LEARNER, x0)
        np.testing.assert_allclose(run.data.states[i], exact, rtol=0, atol=RK4_ATOL)
        # every visited state labelled by the expert exactly
        np.testing.assert_allclose(
            run.data.actions[i], run.data.states[i] @ K_EXPERT.T, rtol=0, atol=LABEL_ATOL
        )
        # the visited states are the learner's, not the expert's
        assert np.max(np.abs(exact - closed_loop_states(K_EXPERT, x0))) > DIFFERENT
    assert [r.source for r in run.rounds] == ["expert", "learner", "learner", "learner"]
    assert all(r.replaced == 0 for r in run.rounds)


def test_dagger_replaces_a_diverging_learner_rollout_by_the_expert(expert_demos):
    def unstable(x):
        return jnp.asarray([[5.0, 5.0]]) @ x  # x2' = 4 x1 + 4 x2: grows like e^{4.8 t}

    def fit(data, steps):
        return None, unstable

    run = train_baseline("dagger", expert_demos, field, expert, BOX, fit, 40, SEED, iterations=2)
    bound = DIVERGENCE_FACTOR * np.max(np.linalg.norm(expert_demos.states, axis=-1))
    assert run.rounds[1].replaced > 0
    assert np.all(np.linalg.norm(run.data.states, axis=-1) <= bound)


def test_dart_noise_is_applied_as_drawn_and_labels_are_clean(expert_demos):
    cov = np.array([[0.09]])
    run = train_baseline(
        "dart", expert_demos, field, expert, BOX, FakeFit(), 40, SEED, iterations=2, noise_cov=cov
    )
    n0, n1 = split_budget(N, 2)
    # the draws of iteration 1, recomputed from the documented key stream 16 + 1
    key_noise = jax.random.split(jax.random.fold_in(jax.random.PRNGKey(SEED), 17))[1]
    eta = dart_noise(key_noise, cov, n1, K)
    assert np.std(eta) > 0.1  # sd 0.3: the noise is there
    for i in range(n1):
        row = n0 + i
        exact = closed_loop_states(K_EXPERT, run.data.x0[row], eta[i])
        np.testing.assert_allclose(run.data.states[row], exact, rtol=0, atol=DART_RK4_ATOL)
        np.testing.assert_allclose(
            run.data.actions[row], run.data.states[row] @ K_EXPERT.T, rtol=0, atol=LABEL_ATOL
        )
    assert run.rounds[1].noise_cov == ((0.09,),)


def test_dart_is_seeded(expert_demos):
    def collect(seed):
        return train_baseline(
            "dart", expert_demos, field, expert, BOX, FakeFit(), 40, seed, noise_cov=[[0.04]]
        ).data.states

    np.testing.assert_array_equal(collect(1), collect(1))
    assert not np.array_equal(collect(1), collect(2))


def test_dart_noise_has_the_requested_covariance():
    cov = np.array([[0.5, 0.2], [0.2, 0.3]])
    eta = dart_noise(jax.random.PRNGKey(0), cov, COV_SAMPLES, 1).reshape(-1, 2)
    np.testing.assert_allclose(np.cov(eta.T), cov, rtol=COV_RTOL, atol=COV_RTOL * 0.3)
    with pytest.raises(SpecError, match="positive semidefinite"):
        dart_noise(jax.random.PRNGKey(0), -cov, 2, 2)


def test_dart_fits_the_noise_to_the_learners_error(expert_demos):
    run = train_baseline("dart", expert_demos, field, expert, BOX, FakeFit(), 40, SEED)
    # iteration 1's covariance: mean of (K_L x - K* x)^2 over iteration 0's used samples
    x = run.data.states[: split_budget(N, 4)[0], :-1].reshape(-1, 2)
    e = x @ (K_LEARNER - K_EXPERT).T
    assert run.rounds[1].noise_cov is not None
    np.testing.assert_allclose(run.rounds[1].noise_cov, (e.T @ e) / len(e), rtol=1e-12)
    np.testing.assert_allclose(error_covariance(learner, expert, x), (e.T @ e) / len(e))


@pytest.mark.parametrize("method", ["dagger", "dart"])
def test_trained_baseline_is_deterministic(tmp_path, method):
    from drip_cert.learn.imitation import train_on_system
    from drip_cert.spec.load import load_spec

    spec = load_spec(write_spec(tmp_path, two_state_spec()))
    st = dataclasses.replace(
        spec.settings.tasil, hidden=(4,), steps=8, trajectories=4, samples=10, heldout=0
    )
    a = train_on_system(spec.system, st, method=method)
    b = train_on_system(spec.system, st, method=method)
    assert a.baseline is not None and a.baseline.labels == 4 * 10
    for (wa, ba), (wb, bb) in zip(a.mlp.params(), b.mlp.params(), strict=True):
        np.testing.assert_array_equal(wa, wb)
        np.testing.assert_array_equal(ba, bb)


def test_settings_accept_every_training_method():
    for m in TRAIN_METHODS:
        assert TasilSettings.from_table({"method": m}).method == m
    with pytest.raises(SpecError, match="tasil.method"):
        TasilSettings.from_table({"method": "dagr"})


@pytest.mark.parametrize(
    "argv",
    [
        ("--method", "dagr"),
        ("--method", "DAgger"),
        ("--compare", "--no-compare"),
    ],
)
def test_train_method_errors_exit_2(tmp_path, capsys, argv):
    spec = write_spec(tmp_path, two_state_spec())
    with pytest.raises(SystemExit) as exc:
        run_cli(capsys, "train", str(spec), "--out", str(tmp_path / "o"), *argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert ("use one of tasil, bc, dagger, dart" in err) or ("not allowed with" in err)


@pytest.mark.slow
def test_train_compare_reports_four_methods_deterministically(tmp_path, capsys):
    text = two_state_spec() + "[tasil]\nhidden = [4]\nsamples = 10\nheldout = 5\n"
    spec = write_spec(tmp_path, text)
    outs = []
    for run in ("a", "b"):
        argv = ("train", str(spec), "--out", str(tmp_path / run), "--compare", "--json")
        code, out, _ = run_cli(capsys, *argv, "--steps", "20", "--trajectories", "4")
        assert code in (0, 1)
        outs.append(json.loads(out)["comparison"])
    rows = outs[0]
    assert list(rows) == list(TRAIN_METHODS)
    for r in rows.values():
        assert r["labels"] == 4 * 10
        assert r["verdict"] in ("certified", "conditional", "not_certified")
        assert r["heldout_gap_mean"] is not None
    assert outs[0] == outs[1]  # same seed, same rows
    code, out, _ = run_cli(
        capsys, "train", str(spec), "--out", str(tmp_path / "c"), "--compare",
        "--steps", "20", "--trajectories", "4",
    )  # fmt: skip
    assert "methods on the same demonstrations and label budget" in out
    for m in TRAIN_METHODS:
        assert f"\n  {m} " in out


def test_train_parser_accepts_every_method():
    from drip_cert.cli import build_parser

    for m in TRAIN_METHODS:
        args = build_parser().parse_args(["train", "s.toml", "--out", "o", "--method", m])
        assert args.method == m and not args.compare
    args = build_parser().parse_args(["train", "s.toml", "--out", "o", "--compare"])
    assert args.compare and not args.no_compare


def test_train_dagger_writes_the_aggregate_and_its_rounds(tmp_path, capsys):
    spec = write_spec(tmp_path, two_state_spec() + "[tasil]\nhidden = [4]\nsamples = 10\n")
    code, out, _ = run_cli(
        capsys, "train", str(spec), "--out", str(tmp_path / "d"), "--method", "dagger",
        "--no-certify", "--no-compare", "--steps", "8", "--trajectories", "4", "--json",
    )  # fmt: skip
    assert code in (0, 1)
    summary = json.loads(out)
    assert summary["method"] == "dagger" and summary["baseline"]["labels"] == 4 * 10
    assert [r["source"] for r in summary["baseline"]["rounds"]] == ["expert"] + ["learner"] * 3
    agg = Demonstrations.load(tmp_path / "d" / "baseline_data.npz")
    expert_set = Demonstrations.load(tmp_path / "d" / "demonstrations.npz")
    assert agg.n_traj == expert_set.n_traj == 4
    np.testing.assert_array_equal(agg.states[0], expert_set.states[0])  # iteration 0
    assert not np.array_equal(agg.states[1:], expert_set.states[1:])  # learner rollouts
