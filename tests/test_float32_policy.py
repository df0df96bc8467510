"""The opt-in float32 policy path: what it computes, that it changes only the policy, that the
engine's invariances hold for it, and the measured effect on the gaps."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.model.mlp import init_mlp
from drip_cert.sim.config import SimConfig
from drip_cert.sim.dtype_effect import DtypeEffect, dtype_effect, policy_dtype_effect
from drip_cert.sim.engine import simulate
from drip_cert.sim.kernel import _advance_jit, build_chunk_fn
from drip_cert.sim.noise import normals
from drip_cert.sim.precision import in_dtype, lower_precision
from drip_cert.sim.resume import settings_hash
from tests.test_engine import _CFG, _arrays, _mlp_model, _x0, _x0_bar

F32_EPS = float(np.finfo(np.float32).eps)

F32_MLP_REL = 64 * F32_EPS
"""The float32 network against a float32 numpy evaluation of the same rounded weights: two
float32 evaluations in another summation order and another tanh, a few dozen ulps of the O(1)
outputs at most."""

F32_PATH_ABS = 1e-4
"""|x32 - x64| of simulated O(1) states after 100 steps: the policy's ~1e-7 relative rounding,
scaled by dt and grown by the closed loop's Lipschitz constant; observed ~1e-7, and 1e-4 still
fails on a wrong network (a different weight moves the states by ~1e-2)."""


def _assert_bitwise(r1, r2):
    for x, y in zip(_arrays(r1), _arrays(r2), strict=True):
        assert x.shape == y.shape
        assert np.array_equal(x, y, equal_nan=True)


@pytest.fixture(scope="module")
def model():
    return _mlp_model()


def test_lower_precision_is_the_network_in_float32():
    """The lowered function equals the MLP evaluated with float32 weights and float32
    arithmetic, differs from float64 by float32 rounding (not zero), and returns float64."""
    pol = init_mlp([4, 64, 64, 4], np.random.default_rng(0))
    low = jax.jit(jax.vmap(lower_precision(pol.apply_jax, 4)))
    x = np.random.default_rng(1).uniform(-1, 1, size=(200, 4))
    y32 = np.asarray(low(jnp.asarray(x)))
    assert y32.dtype == np.float64
    h = x.astype(np.float32)
    for i, (w, b) in enumerate(pol.params()):
        h = h @ w.astype(np.float32).T + b.astype(np.float32)
        h = np.tanh(h) if i < len(pol.weights) - 1 else h
    ref = h.astype(np.float64)
    scale = np.max(np.abs(ref))
    assert np.max(np.abs(y32 - ref)) <= F32_MLP_REL * scale
    y64 = pol.apply_np(x)
    diff = np.max(np.abs(y32 - y64))
    assert 0 < diff <= F32_MLP_REL * scale


def test_lower_precision_inlines_calls_and_keeps_control_flow():
    """jit-wrapped helpers (norm) and custom_jvp functions (relu) are evaluated in float32;
    control flow (cond) is evaluated as written in float64 between casts; all give the float64
    answer up to float32 rounding."""

    def fn(x):
        r = jnp.linalg.norm(x) * jax.nn.relu(x - 0.1)
        return jax.lax.cond(x[0] > 0, lambda v: 2.0 * v, lambda v: -v, r)

    low = lower_precision(fn, 3)
    for x in (jnp.array([0.5, -0.2, 0.9]), jnp.array([-0.5, 0.3, 0.4])):
        y, y64 = low(x), fn(x)
        assert y.dtype == jnp.float64
        np.testing.assert_allclose(np.asarray(y), np.asarray(y64), rtol=F32_MLP_REL, atol=0)
    # the dot of a float32 run really is float32 (the jaxpr says so)
    text = str(jax.make_jaxpr(lower_precision(lambda x: x @ jnp.ones((3, 2)), 3))(jnp.ones(3)))
    assert "f32[2] = dot_general" in text


def test_float32_run_moves_paths_by_rounding_only(model):
    """Same seed, same paths: the float32 policy moves the states by rounding, not more; the
    expert-only scenario does not use the policy and is bit-for-bit unchanged."""
    r64 = simulate(model, _CFG, _x0, _x0_bar, progress=False)
    r32 = simulate(
        model, dataclasses.replace(_CFG, policy_dtype="float32"), _x0, _x0_bar, progress=False
    )
    d = np.abs(r32.sample_paths - r64.sample_paths)
    i_exp = _CFG.scenarios.index("expert_nominal")
    assert np.array_equal(r32.sample_paths[i_exp], r64.sample_paths[i_exp])
    assert 0 < np.max(d) <= F32_PATH_ABS


def test_float32_keeps_chunk_and_worker_invariance(model):
    cfg = dataclasses.replace(_CFG, policy_dtype="float32")
    base = simulate(model, cfg, _x0, _x0_bar, progress=False)
    for cs, workers in ((7, 1), (45, 2)):
        res = simulate(
            model,
            dataclasses.replace(cfg, chunk_size=cs),
            _x0,
            _x0_bar,
            progress=False,
            workers=workers,
        )
        _assert_bitwise(base, res)


def test_policy_dtype_setting_and_hash(model):
    with pytest.raises(SpecError, match="policy_dtype"):
        dataclasses.replace(_CFG, policy_dtype="float16")
    assert "policy_dtype" not in _CFG.to_dict()  # float64 runs keep their resume hash
    cfg32 = dataclasses.replace(_CFG, policy_dtype="float32")
    assert cfg32.to_dict()["policy_dtype"] == "float32"
    assert settings_hash(model, _CFG, _x0, _x0_bar) != settings_hash(model, cfg32, _x0, _x0_bar)


def test_policy_dtype_effect_reports_the_shift_against_the_mc_error(model):
    cfg = SimConfig(
        T=0.2, dt=0.002, n_paths=300, seed=4, l1=_CFG.l1, record_every=10, chunk_size=128
    )
    eff = policy_dtype_effect(model, cfg, _x0, _x0_bar, n_paths=200)
    assert isinstance(eff, DtypeEffect)
    assert eff.n_paths == 200
    assert {g.name for g in eff.gaps} == {g[0] for g in cfg.gaps}
    # float32 rounding is far below the Monte-Carlo error of 200 paths
    assert 0 < eff.max_abs_gap_mean <= F32_PATH_ABS
    assert eff.max_relative_to_ci < 1e-2
    assert "float32" in eff.note() and "200 paths" in eff.note()
    d = eff.to_dict()
    assert d["n_paths"] == 200 and len(d["gaps"]) == len(eff.gaps)
    with pytest.raises(SpecError, match="n_paths"):
        policy_dtype_effect(model, cfg, _x0, _x0_bar, n_paths=0)


# ---------------------------------------------------------------------------- float32 end to end
F32_END_ABS = 1e-4
"""|x32 - x64| of simulated O(1) states after 100 steps with everything in float32: each step
rounds the state, the fields, the policy and the normals at ~6e-8 relative; grown over 100 steps
by the closed loop, observed 4.2e-7. 1e-4 still fails on a wrong computation (another noise
stream or weight moves the states by ~1e-2)."""


def test_float32_end_to_end_is_float32_and_moves_paths_by_rounding_only(model):
    """Same seed, same paths: every scenario (the expert's too) moves by float32 rounding only,
    and the kernel's records are float32."""
    r64 = simulate(model, _CFG, _x0, _x0_bar, progress=False)
    cfg32 = dataclasses.replace(_CFG, dtype="float32")
    r32 = simulate(model, cfg32, _x0, _x0_bar, progress=False)
    d = np.abs(r32.sample_paths - r64.sample_paths)
    i_exp = _CFG.scenarios.index("expert_nominal")
    assert 0 < np.max(d[i_exp]) and 0 < np.max(d) <= F32_END_ABS
    idx = jnp.arange(4, dtype=jnp.uint32)
    recs, _ = build_chunk_fn(model, cfg32, _x0, _x0_bar)(idx)
    assert recs.dtype == jnp.float32


def test_float32_end_to_end_keeps_chunk_and_worker_invariance(model):
    cfg = dataclasses.replace(_CFG, dtype="float32")
    base = simulate(model, cfg, _x0, _x0_bar, progress=False)
    for cs, workers in ((7, 1), (45, 2)):
        res = simulate(
            model,
            dataclasses.replace(cfg, chunk_size=cs),
            _x0,
            _x0_bar,
            progress=False,
            workers=workers,
        )
        _assert_bitwise(base, res)


def test_dtype_setting_hash_and_effect(model):
    with pytest.raises(SpecError, match="dtype"):
        dataclasses.replace(_CFG, dtype="float16")
    assert "dtype" not in _CFG.to_dict()  # float64 runs keep their resume hash
    cfg32 = dataclasses.replace(_CFG, dtype="float32")
    assert settings_hash(model, _CFG, _x0, _x0_bar) != settings_hash(model, cfg32, _x0, _x0_bar)
    cfg = SimConfig(
        T=0.2, dt=0.002, n_paths=300, seed=4, l1=_CFG.l1, record_every=10, chunk_size=128
    )
    eff = dtype_effect(model, dataclasses.replace(cfg, dtype="float32"), _x0, _x0_bar, n_paths=200)
    assert eff.end_to_end and eff.to_dict()["float32"] == "end_to_end"
    assert 0 < eff.max_abs_gap_mean <= F32_END_ABS
    assert "end to end" in eff.note()
    with pytest.raises(SpecError, match="float32"):
        dtype_effect(model, cfg, _x0, _x0_bar)  # nothing in float32: nothing to measure


def _advance_stablehlo(model, cfg, batch: int = 8) -> str:
    """The kernel's advance program for ``cfg``, as StableHLO text before XLA's optimizations."""
    kern = build_chunk_fn(model, cfg, _x0, _x0_bar)
    compiled = kern.compile(batch)
    carry, _ = compiled.start(kern.key, jnp.arange(batch, dtype=jnp.uint32))
    return _advance_jit.lower(
        kern.key,
        carry,
        jnp.uint32(0),
        model=kern.model,
        config=kern.config,
        records_per_call=compiled.records_per_call,
    ).as_text()


def _batched_products_and_row_sums(text: str) -> tuple[int, int]:
    lines = text.splitlines()
    dots = sum("stablehlo.dot_general" in ln and "batching_dims" in ln for ln in lines)
    return dots, sum("stablehlo.reduce" in ln for ln in lines)


def test_float32_step_has_no_batched_products_or_row_reductions(model):
    """The float32 step writes its per-path products (the noise term, Theta lam_hat, g u) and
    its row sums (the guard's norm and finiteness, a norm inside Lambda_mu) as multiply-adds over
    the batch. XLA's CPU backend vectorizes a batched 3x3 / 4x4 product or a 4-column reduction
    across the 4 columns only, as many lanes as in float64, which held the float32 engine at
    ~1.75x float64 (issue 26). The float64 step keeps its forms (the same numbers as before)."""
    d64, r64 = _batched_products_and_row_sums(_advance_stablehlo(model, _CFG))
    assert d64 > 0 and r64 > 0  # the forms the float32 step avoids, so the count can detect them
    cfg32 = dataclasses.replace(_CFG, dtype="float32")
    assert _batched_products_and_row_sums(_advance_stablehlo(model, cfg32)) == (0, 0)


F32_SUM_REL = 8 * F32_EPS
"""A float32 norm of 4 O(1) terms against the same sum in numpy float32: a few roundings of the
4 squares, 3 additions and the sqrt (the compiler may fuse a multiply-add and skip one); a
missing or doubled term moves it by > 1e-2."""


def test_in_dtype_writes_small_float32_sums_in_order():
    """A float32 sum over at most 16 terms (a norm of a state) is written as x0 + x1 + ... in
    order (elementwise once vmapped over the paths); a longer one stays XLA's reduction."""
    x = np.array([0.3, -1.7, 2.9, 0.11])
    norm = in_dtype(lambda v: jnp.sqrt(jnp.sum(v * v)), (jnp.zeros(4),))
    long = in_dtype(lambda v: jnp.sum(jnp.tile(v, 5)), (jnp.zeros(4),))
    assert "reduce_sum" not in {e.primitive.name for e in jax.make_jaxpr(norm)(x).jaxpr.eqns}
    assert "reduce_sum" in {e.primitive.name for e in jax.make_jaxpr(long)(x).jaxpr.eqns}
    x32 = x.astype(np.float32)
    expect = float(np.sqrt(np.sum(x32 * x32, dtype=np.float32)))
    got = jax.jit(norm)(x)
    assert got.dtype == np.float32
    assert abs(float(got) - expect) <= F32_SUM_REL * expect
    assert float(jax.jit(long)(x)) == pytest.approx(5 * float(np.sum(x32)), rel=F32_SUM_REL)


def test_float32_normals_are_the_same_increments_rounded():
    """The float32 noise hashes the same counters: each normal is within float32 resolution of
    the float64 one (bulk |z| < 3: F32_Z_BULK_ABS), and no normal is infinite."""
    key = jax.random.fold_in(jax.random.PRNGKey(5), 2)
    idx = jnp.arange(4096, dtype=jnp.uint32)
    z64 = np.asarray(normals(key, idx, jnp.uint32(7), 4))
    z32 = np.asarray(normals(key, idx, jnp.uint32(7), 4, jnp.float32))
    assert z32.dtype == np.float32 and np.all(np.isfinite(z32))
    bulk = np.abs(z64) < 3.0
    assert np.max(np.abs(z32[bulk] - z64[bulk])) < F32_Z_BULK_ABS
    assert np.max(np.abs(z32)) < 5.4


F32_Z_BULK_ABS = 2e-5
"""float32 normals against float64 for |z| < 3: the float32 u is the midpoint of the 2^-22-wide
bin the float64 u lies in, so |du| <= 2^-23 = 1.2e-7, and dz/du = sqrt(pi/2) e^{z^2/2} <= 113 at
|z| = 3: |dz| <= 1.35e-5, plus a few float32 ulps of erfinv (~1e-6); observed 1.43e-5."""


def test_cli_dtype_reaches_the_simulation(monkeypatch, tmp_path):
    import drip_cert.workflows as workflows
    from drip_cert.cli import main
    from tests.helpers import EXAMPLES

    seen = {}

    class _Report:
        status = "holds"

        def to_dict(self):
            return {}

    def fake(*_, **kw):
        seen.update(kw)
        return _Report()

    monkeypatch.setattr(workflows, "validate_spec", fake)
    spec = EXAMPLES / "regression_ci" / "plant.toml"
    main(["validate", str(spec), "--dtype", "float32", "--json"])
    assert seen["dtype"] == "float32" and seen["policy_dtype"] == "float64"
