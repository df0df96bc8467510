"""Tests of the Monte-Carlo engine (drip_cert.sim: config, kernel, driver, resume, result)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import scipy.stats

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1Params
from drip_cert.errors import SpecError
from drip_cert.model.mlp import init_mlp
from drip_cert.model.numeric import make_model
from drip_cert.sim import kernel
from drip_cert.sim.config import STATUS_CAP, STATUS_NONFINITE, SimConfig
from drip_cert.sim.engine import simulate
from drip_cert.sim.kernel import build_chunk_fn
from tests.helpers import MC_Z, example_spec

POINT_MASS_ATOL = 1e-15
"""At t = 0 the law is a point mass (variance 0): the sample mean of 20000 equal O(1) values
may be off by an ulp."""

RECURSION_RTOL = 1e-13
"""x0 r^k (one power) against k multiplications by r (the engine's recursion, k <= 100): a few
ulps per step at most."""

L1_GAP_RATIO = 0.1
"""Upper bound on (uncertainty gap with L1) / (without L1) for the constant matched disturbance
below. Derivation: the steady residual is (1 - e^{-lambda_s T_s}) = 0.02 of the disturbance
(L1-DRAC (15b) converges to e^{-lambda_s T_s} sigma), and the start-up transient lets the
disturbance act unopposed for about T_s + 1/omega = 0.012 s against a plant time constant of
1 s, i.e. ~0.012 of the open-loop offset; 0.1 leaves a factor 3 for the Euler and cross terms."""


THETA_ATOL = 1e-13
"""Two O(1)-conditioned 4x4 solves agree to a few ulps."""

NORM_RTOL = 1e-14
"""numpy's norm and the engine's left-to-right sum of squares differ by a few ulps."""

EULER_RTOL = 2.5e-3
"""Global error of explicit Euler on a stable linear ODE over [0, T], relative: about
dt * T / 2 = 2.5e-3 for dt = 1e-3, T = 5 and unit-size eigenvalues."""

EULER_ATOL = EULER_RTOL * 0.5
"""The same relative error of the matched disturbance's size 0.5, for gaps near their start at
exactly 0."""


def _ou_model(a: float, s: float):
    """dX = -a X dt + s dW (scenario learned_true); the nominal processes are the ODE x' = -a x."""
    return make_model(
        1,
        1,
        1,
        f=lambda t, x: -a * x,
        g=np.ones((1, 1)),
        expert=lambda x: jnp.zeros(1),
        learned=lambda x: jnp.zeros(1),
        lam_sigma=lambda t, x: s * jnp.ones((1, 1)),
        name="ou",
    )


def test_euler_maruyama_on_ornstein_uhlenbeck():
    a, s, x0, dt, n_steps, n_paths = 1.3, 0.7, 1.5, 0.01, 100, 20_000
    model = _ou_model(a, s)
    cfg = SimConfig(
        T=n_steps * dt,
        dt=dt,
        n_paths=n_paths,
        chunk_size=n_paths,
        scenarios=("learned_nominal", "learned_true"),
        record_every=25,
        p_max=2,
        seed=11,
    )

    def sampler(key):
        return jnp.array([x0])

    fn = build_chunk_fn(model, cfg, sampler)
    recs, codes = fn(jnp.arange(n_paths, dtype=jnp.uint32))
    recs = np.asarray(recs)
    assert np.all(np.asarray(codes) == 0)
    r = 1.0 - a * dt
    for i, t in enumerate(cfg.record_times):
        k = int(round(t / dt))
        # exact law of the Euler-Maruyama recursion X_{k+1} = r X_k + s sqrt(dt) N(0,1)
        mean = x0 * r**k
        var = s**2 * dt * (1.0 - r ** (2 * k)) / (1.0 - r**2)
        xs = recs[i, 1, :, 0]
        assert abs(xs.mean() - mean) <= MC_Z * math.sqrt(var / n_paths) + POINT_MASS_ATOL
        if k:
            assert abs(xs.var(ddof=1) - var) <= MC_Z * var * math.sqrt(2.0 / (n_paths - 1))
            # the nominal ODE is the Euler recursion without noise: exactly the mean
            np.testing.assert_allclose(recs[i, 0, :, 0], mean, rtol=RECURSION_RTOL)
    # the continuous-time OU law is within the O(dt) scheme bias of the Euler law at T
    t_end = n_steps * dt
    var_ct = s**2 / (2 * a) * (1.0 - math.exp(-2 * a * t_end))
    assert abs(var - var_ct) <= a * dt * var_ct  # first-order bias of Euler for OU

    # the statistics pipeline: r_t = |X_t - x'_t| is |N(0, var)|
    res = simulate(model, cfg, sampler, progress=False)
    g = res.gap("uncertainty_true")
    v = var  # at T
    assert abs(g.moments[0, -1] - v) <= MC_Z * math.sqrt(2.0) * v / math.sqrt(n_paths)
    assert abs(g.moments[1, -1] - 3 * v**2) <= MC_Z * math.sqrt(96.0) * v**2 / math.sqrt(n_paths)
    m_abs = math.sqrt(2 * v / math.pi)
    assert abs(g.mean[-1] - m_abs) <= MC_Z * math.sqrt(v * (1 - 2 / math.pi) / n_paths)
    # the t interval's half width is t_{0.975} * s / sqrt(N), s the sample sd of |N(0, v)|;
    # s has relative standard error sqrt((kurt - 1) / (4 N)), kurt = 3 + 8(pi-3)/(pi-2)^2
    half = g.ci_high[-1] - g.mean[-1]
    sd_abs = math.sqrt(v * (1 - 2 / math.pi))
    kurt = 3 + 8 * (math.pi - 3) / (math.pi - 2) ** 2
    rel_se = math.sqrt((kurt - 1) / (4 * n_paths))
    expected = scipy.stats.t.ppf(0.975, n_paths - 1) * sd_abs / math.sqrt(n_paths)
    assert half == pytest.approx(expected, rel=MC_Z * rel_se)


def _mlp_model(seed: int = 0, uncertain: bool = True, learned_is_expert: bool = False):
    rng = np.random.default_rng(seed)
    h = init_mlp([3, 8, 3], rng)
    pol = init_mlp([3, 16, 2], rng)
    g = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]])

    def expert(x):
        return -0.5 * x[:2] + 0.2 * h.apply_jax(x)[:2]

    def learned(x):
        return expert(x) + 0.1 * pol.apply_jax(x)

    kwargs = {}
    if uncertain:
        kwargs = {
            "lam_mu": lambda t, x: (0.2 + 0.05 * jnp.sqrt(jnp.sum(x * x))) * jnp.ones(3),
            "lam_sigma": lambda t, x: (
                (0.1 + 0.05 * jnp.sqrt(jnp.sqrt(jnp.sum(x * x)))) * jnp.eye(3)
            ),
        }
    return make_model(
        3,
        2,
        3,
        f=lambda t, x: -1.0 * x - 0.3 * h.apply_jax(x),
        g=g,
        expert=expert,
        learned=expert if learned_is_expert else learned,
        name="mlp3",
        **kwargs,
    )


def _x0(key):
    return jax.random.uniform(key, (3,), minval=-1.0, maxval=1.0)


def _x0_bar(key):
    return 0.1 + jax.random.uniform(key, (3,), minval=-1.0, maxval=1.0)


_L1 = L1Params(omega=50.0, lambda_s=10.0, Ts=0.01, dt=0.002)
_CFG = SimConfig(
    T=0.2,
    dt=0.002,
    n_paths=90,
    chunk_size=32,
    l1=_L1,
    record_every=10,
    n_sample_paths=5,
    p_max=3,
    kappas=(0.05, 0.2),
    w2_times=(0.1, 0.2),
    w2_points=30,
    seed=5,
)


def _arrays(res):
    out = [res.sample_paths, res.sample_status]
    for g in res.gaps:
        out += [g.mean, g.ci_low, g.ci_high, g.moments, g.tail_freq, g.sample_max, g.path_max]
    out.append(np.array([(w.w2, w.baseline_a, w.baseline_b) for w in res.w2]))
    return out


def _assert_bitwise(r1, r2):
    a1, a2 = _arrays(r1), _arrays(r2)
    assert len(a1) == len(a2)
    for x, y in zip(a1, a2):
        assert x.shape == y.shape
        assert np.array_equal(x, y, equal_nan=True)


@pytest.fixture(scope="module")
def model():
    return _mlp_model()


@pytest.fixture(scope="module")
def base_result(model):
    return simulate(model, _CFG, _x0, _x0_bar, progress=False)


def test_chunk_size_invariance_bit_for_bit(base_result, model):
    for cs in (7, 45):
        res = simulate(
            model, dataclasses.replace(_CFG, chunk_size=cs), _x0, _x0_bar, progress=False
        )
        _assert_bitwise(base_result, res)


def test_gap_readout_maps_the_gaps_and_keeps_the_paths(base_result, model):
    """gap_readout = M: each gap is ||M (a - b)||. With M = 2 I every gap statistic doubles
    exactly (a power of two is exact in floating point; moments scale by 4^p); the recorded
    paths are untouched; a rotation leaves the norms unchanged up to rounding; and the result
    is still bit-for-bit independent of the chunk size."""
    two = tuple(tuple(2.0 * float(i == j) for j in range(3)) for i in range(3))
    res = simulate(model, dataclasses.replace(_CFG, gap_readout=two), _x0, _x0_bar, progress=False)
    assert np.array_equal(res.sample_paths, base_result.sample_paths, equal_nan=True)
    for g, g0 in zip(res.gaps, base_result.gaps):
        assert np.array_equal(g.mean, 2.0 * g0.mean)
        assert np.array_equal(g.path_max, 2.0 * g0.path_max)
    c, s_ = math.cos(0.7), math.sin(0.7)
    rot = ((c, -s_, 0.0), (s_, c, 0.0), (0.0, 0.0, 1.0))
    cfg = dataclasses.replace(_CFG, gap_readout=rot)
    r1 = simulate(model, cfg, _x0, _x0_bar, progress=False)
    for g, g0 in zip(r1.gaps, base_result.gaps):
        # the rotation rounds each component too: ten times the norm tolerance
        np.testing.assert_allclose(g.mean, g0.mean, rtol=NORM_RTOL * 10, atol=POINT_MASS_ATOL)
    r2 = simulate(model, dataclasses.replace(cfg, chunk_size=7), _x0, _x0_bar, progress=False)
    _assert_bitwise(r1, r2)
    with pytest.raises(SpecError, match="gap_readout"):
        dataclasses.replace(_CFG, gap_readout=((1.0, 0.0, 0.0),) * 3)  # singular


@pytest.mark.parametrize(
    ("chunk_size", "workers"),
    [
        (32, 1),  # three chunks one after another
        (90, 3),  # one chunk split into three concurrent sub-batches of 30
        (45, 5),  # two chunks, each split in two sub-batches of 23 (the last one padded)
    ],
)
def test_worker_count_invariance_bit_for_bit(base_result, model, chunk_size, workers):
    cfg = dataclasses.replace(_CFG, chunk_size=chunk_size)
    res = simulate(model, cfg, _x0, _x0_bar, progress=False, workers=workers)
    _assert_bitwise(base_result, res)


def test_split_into_calls_and_progress_bar_change_no_bit(base_result, model, monkeypatch, capsys):
    """One recorded time per kernel call (the finest split), with the bar on: the same bits."""
    monkeypatch.setattr(kernel, "MIN_CALL_PATH_STEPS", 1)
    cfg = dataclasses.replace(_CFG, chunk_size=90)
    res = simulate(model, cfg, _x0, _x0_bar, progress=True, workers=1)
    _assert_bitwise(base_result, res)
    assert "path-step" in capsys.readouterr().err  # the bar is on stderr


def test_kernel_reports_each_call(model, monkeypatch):
    """``on_block`` hears of every call once, in order, and the calls cover the records."""
    idx = jnp.arange(16, dtype=jnp.uint32)
    monkeypatch.setattr(kernel, "MIN_CALL_PATH_STEPS", 1 << 40)  # all records in one call
    recs, codes1 = build_chunk_fn(model, _CFG, _x0, _x0_bar)(idx)
    # a record block is 10 steps of 16 paths in 4 scenarios: two of them per call
    monkeypatch.setattr(kernel, "MIN_CALL_PATH_STEPS", 2 * 10 * 16 * 4)
    compiled = build_chunk_fn(model, _CFG, _x0, _x0_bar).compile(16)
    assert (compiled.records_per_call, compiled.n_calls) == (2, 5)
    heard = []
    blocks, codes = compiled(idx, heard.append)
    assert heard == [2] * 5
    assert np.array_equal(np.concatenate(blocks), np.asarray(recs))
    assert np.array_equal(np.asarray(codes), np.asarray(codes1))


def test_workers_must_be_positive(model):
    with pytest.raises(SpecError, match="workers"):
        simulate(model, _CFG, _x0, _x0_bar, progress=False, workers=0)


def test_seed_determinism(base_result, model):
    again = simulate(model, _CFG, _x0, _x0_bar, progress=False)
    _assert_bitwise(base_result, again)
    other = simulate(model, dataclasses.replace(_CFG, seed=6), _x0, _x0_bar, progress=False)
    assert not np.array_equal(base_result.gap("total_l1").mean[1:], other.gap("total_l1").mean[1:])


def test_result_contents_and_save(base_result, tmp_path):
    res = base_result
    assert res.complete and res.n_paths_done == 90
    assert [g.name for g in res.gaps] == [
        "policy",
        "total_true",
        "uncertainty_true",
        "total_l1",
        "uncertainty_l1",
    ]
    # independent D_bar: the true processes start elsewhere, the nominal ones together
    assert res.gap("total_true").mean[0] > 0.0
    assert res.gap("policy").mean[0] == 0.0
    # sample paths: the first path's initial states come from the two samplers
    assert np.array_equal(res.sample_paths[0, 0, 0], res.sample_paths[1, 0, 0])
    assert not np.array_equal(res.sample_paths[0, 0, 0], res.sample_paths[2, 0, 0])
    assert np.array_equal(res.sample_paths[2, :, 0], res.sample_paths[3, :, 0])
    assert len(res.w2) == 2 * 5
    for w in res.w2:
        assert w.w2 >= 0 and w.baseline_a >= 0 and w.baseline_b >= 0
    out = res.save(tmp_path / "out")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_paths_done"] == 90
    with np.load(out / "arrays.npz") as data:
        np.testing.assert_array_equal(data["total_l1.mean"], res.gap("total_l1").mean)
        np.testing.assert_array_equal(data["policy.path_max"], res.gap("policy").path_max)
    # per-path maxima over the recorded times: one per valid path, and their max is the sample max
    for g in res.gaps:
        assert g.path_max.shape == (g.n,)
        assert g.path_max.max() == g.sample_max.max()
    # the kept sample paths give the first paths' policy-gap maxima directly
    lead = res.sample_paths[1] - res.sample_paths[0]  # learned_nominal - expert_nominal
    np.testing.assert_allclose(
        res.gap("policy").path_max[: lead.shape[0]],
        np.linalg.norm(lead, axis=-1).max(axis=1),
        rtol=NORM_RTOL,
    )
    assert not list(out.glob("*.tmp"))


def test_gaps_exactly_zero_without_uncertainty_and_with_expert_policy():
    model = _mlp_model(uncertain=False, learned_is_expert=True)
    res = simulate(model, dataclasses.replace(_CFG, w2_times=()), _x0, progress=False)
    for g in res.gaps:
        assert g.n == 90
        assert np.all(g.mean == 0.0), g.name
        assert np.all(g.moments == 0.0), g.name
        assert np.all(g.tail_freq == 0.0), g.name
    assert res.gap("total_l1").sample_max.max() == 0.0


def _square_model():
    """x' = x^2: finite-time blow-up at t = 1/x0 for x0 > 0."""
    return make_model(
        1,
        1,
        1,
        f=lambda t, x: x * x,
        g=np.ones((1, 1)),
        expert=lambda x: 0.0 * x,
        learned=lambda x: 0.0 * x,
        name="square",
    )


def _x0_two_point(key):
    # 0.5 (bounded on [0, 1]) or 3 (blows up at t = 1/3), each with probability 1/2
    return jnp.where(jax.random.bernoulli(key), 3.0, 0.5) * jnp.ones(1)


@pytest.mark.parametrize("cap, code", [(1e6, STATUS_CAP), (1e300, STATUS_NONFINITE)])
def test_diverging_paths_get_codes_and_run_completes(cap, code):
    n = 64
    cfg = SimConfig(
        T=1.0,
        dt=0.01,
        n_paths=n,
        chunk_size=24,
        l1=L1Params(50.0, 10.0, 0.02, 0.01),
        record_every=10,
        n_sample_paths=n,
        divergence_cap=cap,
        p_max=2,
    )
    res = simulate(_square_model(), cfg, _x0_two_point, progress=False)
    assert res.complete
    x0 = res.sample_paths[0, :, 0, 0]
    blowing = x0 == 3.0
    assert 0 < blowing.sum() < n
    for st in res.status:
        assert st.diverged_fraction == blowing.mean(), st.name
        assert (st.n_capped if code == STATUS_CAP else st.n_nonfinite) == blowing.sum()
    assert np.all(res.sample_status[:, blowing] == code)
    assert np.all(res.sample_status[:, ~blowing] == 0)
    # frozen paths stay finite and below the cap; the statistics use the bounded paths only
    assert np.all(np.isfinite(res.sample_paths))
    assert np.all(np.abs(res.sample_paths) <= cap)
    for g in res.gaps:
        assert g.n == n - blowing.sum()
        assert np.all(np.isfinite(g.mean))


def test_l1_cancels_constant_matched_disturbance():
    # x1' = x2, x2' = -x1 - 2 x2 + u + sigma: sigma = 0.5 is matched (g = [0, 1]^T)
    model = make_model(
        2,
        1,
        1,
        f=lambda t, x: jnp.array([x[1], -x[0] - 2.0 * x[1]]),
        g=np.array([[0.0], [1.0]]),
        expert=lambda x: jnp.zeros(1),
        learned=lambda x: jnp.zeros(1),
        lam_mu=lambda t, x: jnp.array([0.0, 0.5]),
        name="matched",
    )
    cfg = SimConfig(
        T=5.0,
        dt=1e-3,
        n_paths=16,
        chunk_size=16,
        l1=L1Params(omega=100.0, lambda_s=10.0, Ts=2e-3, dt=1e-3),
        scenarios=("learned_nominal", "learned_true", "learned_l1_true"),
        record_every=50,
    )
    res = simulate(
        model, cfg, lambda k: jax.random.uniform(k, (2,), minval=-1, maxval=1), progress=False
    )
    without = res.gap("uncertainty_true")
    with_l1 = res.gap("uncertainty_l1")
    # without L1, e = X - x' solves e' = A e + g sigma, e(0) = 0 (double pole at -1):
    # e1 = 0.5 (1 - (1 + t) e^{-t}), e2 = 0.5 t e^{-t}
    t = res.times
    e_exact = np.hypot(0.5 * (1 - (1 + t) * np.exp(-t)), 0.5 * t * np.exp(-t))
    np.testing.assert_allclose(without.mean, e_exact, rtol=EULER_RTOL, atol=EULER_ATOL)
    assert with_l1.max_mean <= L1_GAP_RATIO * without.max_mean


def test_resume_after_interruption_is_bit_for_bit(base_result, model, tmp_path):
    run_dir = tmp_path / "run"
    part = simulate(model, _CFG, _x0, _x0_bar, run_dir=run_dir, stop_after_chunks=2)
    assert not part.complete and part.n_paths_done == 64
    full = simulate(model, _CFG, _x0, _x0_bar, run_dir=run_dir)
    assert full.complete and full.n_paths_done == 90
    _assert_bitwise(base_result, full)
    # a finished run directory is reused without simulating
    again = simulate(model, _CFG, _x0, _x0_bar, run_dir=run_dir)
    assert again.compile_s == 0.0
    _assert_bitwise(base_result, again)
    with pytest.raises(SpecError, match="other settings"):
        simulate(model, dataclasses.replace(_CFG, seed=99), _x0, _x0_bar, run_dir=run_dir)


def test_config_errors_name_the_field():
    with pytest.raises(SpecError, match="SimConfig.dt"):
        SimConfig(T=1.0, dt=0.3, n_paths=10)
    with pytest.raises(SpecError, match="SimConfig.record_every"):
        SimConfig(T=1.0, dt=0.01, n_paths=10, record_every=7)
    with pytest.raises(SpecError, match="SimConfig.l1"):
        SimConfig(T=1.0, dt=0.01, n_paths=10)
    with pytest.raises(SpecError, match="SimConfig.l1"):
        SimConfig(T=1.0, dt=0.01, n_paths=10, l1=L1Params(1.0, 1.0, 0.02, 0.002))
    with pytest.raises(SpecError, match="SimConfig.scenarios"):
        SimConfig(T=1.0, dt=0.01, n_paths=10, scenarios=("expert",))
    with pytest.raises(SpecError, match="SimModel.f"):
        make_model(2, 1, 1, f=lambda t, x: x[:1], g=np.ones((2, 1)), expert=lambda x: x[:1])


def test_theta_ad_default_equals_first_rows_of_gbar_inverse():
    # Theta_ad = [I_m 0] [g g_perp]^{-1} (L1-DRAC Assumption 1), g_perp from the SVD of g
    from drip_cert.model.numeric import theta_ad_from_g

    g = np.array([[1.0, 0.2], [0.0, 1.0], [0.5, -0.3], [0.1, 0.0]])
    g_perp = np.linalg.svd(g)[0][:, 2:]
    direct = np.linalg.inv(np.hstack([g, g_perp]))[:2]
    via_pinv = np.asarray(theta_ad_from_g(lambda t, x: jnp.asarray(g), 4)(0.0))
    np.testing.assert_allclose(via_pinv, direct, rtol=0, atol=THETA_ATOL)


JAC_RTOL = 1e-12
"""The symbolic Jacobian lowered to jax and forward-mode autodiff of the lowered closed loop are
two float64 evaluations of one expression: they agree to a few ulps of its O(1) entries."""


def test_system_numeric_is_the_one_cached_view_with_exact_jacobians():
    """``System.numeric`` is built once and is what the engine and the analysis both read."""
    from drip_cert.model.numeric import SimModel, closed_loop_jacobian
    from drip_cert.spec import load_spec

    s = load_spec(example_spec("nonlinear_2d")).system
    x1, x2 = s.states
    s = s.with_learned([-0.45 * x2 + 0.05 * x1])
    num = s.numeric
    assert isinstance(num, SimModel) and s.numeric is num
    assert (num.n, num.m, num.d, num.name) == (2, 1, 2, s.name)
    x = jnp.array([0.3, -0.7])
    for jac, pol in ((num.jac_expert, num.expert), (num.jac_learned, num.learned)):
        auto = closed_loop_jacobian(num.f, num.g, pol)(0.5, x)
        np.testing.assert_allclose(np.asarray(jac(0.5, x)), np.asarray(auto), rtol=JAC_RTOL)
    # a view from plain functions gets the autodiff Jacobians; none without a learned policy
    plain = make_model(2, 1, 1, f=num.f, g=num.g, expert=num.expert)
    assert plain.jac_learned is None
    np.testing.assert_allclose(
        np.asarray(plain.jac_expert(0.5, x)), np.asarray(num.jac_expert(0.5, x)), rtol=JAC_RTOL
    )
