"""Recorded data against a certificate (``drip-cert validate SPEC --data FILE``).

Mathematics first: the data path computes the same numbers as the Monte-Carlo path, bit for bit,
when given the engine's own trajectories (same accumulation, same checks); the minimum path count
is the closed form of the Clopper-Pearson bound. Then the command: data recorded with the
deployed controller in a numpy loop hold (exit 0), the same data with a gap pushed beyond
``rho_L1`` violate (exit 1), malformed files are exit 2 with a message naming the array.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from drip_cert.errors import FingerprintError, SpecError
from drip_cert.model.fingerprint import Fingerprint, design_fingerprint, fingerprint_of
from drip_cert.spec import load_spec
from drip_cert.validate.checks import HOLDS, NOT_CHECKED, VIOLATED
from drip_cert.validate.data import (
    GAPS,
    SCENARIOS,
    load_recorded,
    minimum_paths,
    validate_data,
)
from tests.helpers import by_name, example_spec, run_cli, write_spec

SPEC = example_spec("pendulum")
SEED = 3
N_PATHS = 60
T_DATA = 0.5  # seconds of data (the certified horizon is 10 s: the checks cover [0, 0.5])
RECORD_EVERY = 10


# -------------------------------------------------------------------------- recording
def _record(ctrl, policy, n_paths: int, seed: int) -> dict[str, np.ndarray]:
    """The user's loop: the pendulum's four processes in numpy, Euler(-Maruyama) with the
    controller's dt, the deployed controller and policy (README's worked example)."""
    rng = np.random.default_rng(seed)
    dt = ctrl.dt
    n_steps = round(T_DATA / dt / RECORD_EVERY) * RECORD_EVERY
    x0 = rng.uniform(-0.5, 0.5, size=(n_paths, 2))

    def f(x):
        return np.stack([x[:, 1], -9.81 * np.sin(x[:, 0]) - 0.5 * x[:, 1]], 1)

    def g_u(u):
        return np.stack([np.zeros(len(u)), u], 1)

    def lam_mu(x):
        return np.stack([np.zeros(len(x)), 0.1 * np.sin(x[:, 0]) + 0.05 * np.tanh(x[:, 1])], 1)

    def expert(x):
        return 9.81 * np.sin(x[:, 0]) - 4 * x[:, 0] - 4 * x[:, 1]

    xs = {s: x0.copy() for s in SCENARIOS}
    rec = {s: [x0.copy()] for s in SCENARIOS}
    ctrl.reset(x0)
    for j in range(n_steps):
        dw = math.sqrt(dt) * rng.standard_normal(n_paths)
        noise = np.stack([np.zeros(n_paths), 0.05 * dw], 1)
        x = xs["expert_nominal"]
        xs["expert_nominal"] = x + dt * (f(x) + g_u(expert(x)))
        x = xs["learned_nominal"]
        xs["learned_nominal"] = x + dt * (f(x) + g_u(policy(x)[:, 0]))
        x = xs["learned_true"]
        xs["learned_true"] = x + dt * (f(x) + g_u(policy(x)[:, 0]) + lam_mu(x)) + noise
        x = xs["learned_l1_true"]
        u = ctrl.step(j * dt, x)[:, 0]
        xs["learned_l1_true"] = x + dt * (f(x) + g_u(u) + lam_mu(x)) + noise
        if (j + 1) % RECORD_EVERY == 0:
            for s in SCENARIOS:
                rec[s].append(xs[s].copy())
    out = {s: np.stack(v, axis=1) for s, v in rec.items()}
    out["t"] = np.arange(n_steps // RECORD_EVERY + 1) * (RECORD_EVERY * dt)
    p = ctrl.params
    out["l1_design"] = np.array([p.omega, p.lambda_s, p.Ts])
    out["fingerprint"] = np.array(str(ctrl.fingerprint))  # what the data were recorded with
    return out


@pytest.fixture(scope="module")
def deployed():
    from drip_cert.deploy import certificate_of, l1drac_controller, learned_policy

    cert = certificate_of(SPEC)
    ts = cert.l1.design.Ts
    ctrl = l1drac_controller(cert, dt=ts / math.ceil(ts / 1e-3))  # the spec's dt, rounded down
    return cert, ctrl, learned_policy(SPEC)


@pytest.fixture
def certified_once(monkeypatch, deployed):
    """The command with the module's certificate instead of certifying again (seconds each):
    reading, checking and comparing the data run as in the real command."""
    import drip_cert.bounds.certificate as certificate

    monkeypatch.setattr(certificate, "certify", lambda spec, **kw: deployed[0])


@pytest.fixture(scope="module")
def recorded(deployed):
    _, ctrl, policy = deployed
    return _record(ctrl, policy, N_PATHS, SEED)


def _save(tmp_path, arrays, name="data.npz"):
    path = tmp_path / name
    np.savez(path, **arrays)
    return path


def _validate(cert, path):
    return validate_data(cert, load_recorded(path), n_state=2, certified_horizon=10.0)


# ------------------------------------------------------------------------- mathematics
def test_names_agree_with_the_engine():
    from drip_cert.sim.config import GAPS as ENGINE_GAPS
    from drip_cert.sim.config import SCENARIOS as ENGINE_SCENARIOS
    from drip_cert.sim.config import SimConfig
    from drip_cert.validate.data import DEFAULT_LEVEL

    assert SCENARIOS == ENGINE_SCENARIOS
    assert GAPS == ENGINE_GAPS
    default = SimConfig(T=1.0, dt=0.1, n_paths=1, scenarios=("expert_nominal",))
    assert DEFAULT_LEVEL == default.ci_level


@pytest.mark.parametrize(
    "delta, level", [(0.1, 0.95), (0.2, 0.95), (0.05, 0.99), (0.5, 0.9), (0.01, 0.999)]
)
def test_minimum_paths_is_the_clopper_pearson_closed_form(delta, level):
    """At k = N the one-sided lower bound is (1 - level)^(1/N): it exceeds delta first at
    N = floor(log(1 - level) / log(delta)) + 1."""
    n = minimum_paths(delta, level)
    assert n == math.floor(math.log(1 - level) / math.log(delta)) + 1
    assert (1 - level) ** (1 / n) > delta >= (1 - level) ** (1 / (n - 1))


def _stub_certificate(rho_tasil, rho_l1, kappa, ts=0.01):
    from drip_cert.bounds.certificate import Claims

    design = SimpleNamespace(p=1, kappa=kappa, delta=0.2, omega=30.0, lambda_s=8.0, Ts=ts)
    stub = SimpleNamespace(
        rho_tasil=rho_tasil,
        rho_l1=rho_l1,
        rho_sde=None,
        rho=None,
        tasil=SimpleNamespace(delta=0.1),
        l1=SimpleNamespace(feasible=True, design=design),
        coordinates=None,
        to_dict=lambda: {},
    )
    stub.claims = lambda: Claims.of(stub)
    return stub


def test_the_engine_own_trajectories_as_data_give_the_engine_checks_bit_for_bit():
    """Two routes to one number: the engine's checks of its run, and the data path fed the
    same run's trajectories (all paths kept, recorded every step). Equal to the last bit."""
    from drip_cert._jax import jax, jnp
    from drip_cert.control.l1drac import L1Params
    from drip_cert.model.numeric import make_model
    from drip_cert.sim.config import SimConfig
    from drip_cert.sim.engine import simulate
    from drip_cert.validate.checks import checks_from_result
    from drip_cert.validate.run import _thresholds

    model = make_model(
        2,
        1,
        2,
        lambda t, x: jnp.array([-x[0] + x[1], -x[1]]),
        np.array([[0.0], [1.0]]),
        lambda x: jnp.array([-x[0] - 2 * x[1]]),
        learned=lambda x: jnp.array([-1.05 * x[0] - 2 * x[1]]),
        lam_mu=lambda t, x: jnp.array([0.2 * jnp.sin(x[1]), 0.3]),
        lam_sigma=lambda t, x: 0.1 * jnp.eye(2),
    )
    n, dt, T = 40, 0.01, 1.0
    cert = _stub_certificate(rho_tasil=0.05, rho_l1=0.02, kappa=0.03, ts=2 * dt)
    kappas = _thresholds(cert.claims())
    cfg = SimConfig(
        T=T,
        dt=dt,
        n_paths=n,
        seed=1,
        chunk_size=n,
        l1=L1Params(30.0, 8.0, 2 * dt, dt),
        record_every=1,
        n_sample_paths=n,
        kappas=kappas,
        p_max=4,
        w2_times=(T,),
        w2_points=n // 2,
    )
    sampler = lambda key: jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0)  # noqa: E731
    res = simulate(model, cfg, sampler, workers=1)
    ref = checks_from_result(
        res, rho_tasil=0.05, delta_tasil=0.1, rho_l1=0.02, p=1, kappa=0.03, delta_l1=0.2
    )
    arrays = {s: res.sample_paths[i] for i, s in enumerate(cfg.scenarios)}
    arrays["t"] = res.times
    from drip_cert.validate.data import _checked

    data = _checked(arrays, "engine", "npz", None)
    rep = validate_data(cert, data, n_state=2, certified_horizon=T, accept_unfingerprinted=True)
    got = by_name(rep.checks)
    assert [c.name for c in rep.checks] == [c.name for c in ref]
    for c in ref:
        assert got[c.name].to_dict() == c.to_dict(), c.name
    assert {c.status for c in ref} >= {HOLDS, VIOLATED}  # both outcomes exercised
    assert [w.to_dict() for w in rep.result.w2] == [w.to_dict() for w in res.w2]


def test_missing_processes_are_not_checked_and_say_what_to_add(tmp_path, deployed, recorded):
    cert = deployed[0]
    nominal = {k: recorded[k] for k in ("t", "expert_nominal", "learned_nominal", "fingerprint")}
    rep = _validate(cert, _save(tmp_path, nominal))
    checks = by_name(rep.checks)
    assert checks["policy_radius"].status == HOLDS
    for name in ("uncertainty_gap", "uncertainty_L2_norm", "tail_frequency", "total_tail"):
        assert checks[name].status == NOT_CHECKED
        assert "not in the data: give learned_l1_true" in checks[name].reason
    assert rep.status == HOLDS
    assert any("not in the data" in n for n in rep.notes)


def test_gap_series_and_csv_give_the_trajectories_numbers(tmp_path, deployed, recorded):
    """The same paths as trajectories (.npz), as gap series (.npz) and as long CSV: equal checks
    (the CSV prints 17 significant digits: float64 round trips exactly)."""
    from drip_cert.numerics.stats import norms_sequential

    cert = deployed[0]
    ref = [c.to_dict() for c in _validate(cert, _save(tmp_path, recorded)).checks]
    gaps = {k: recorded[k] for k in ("t", "l1_design", "fingerprint")}
    for g, a, b in GAPS:
        gaps[f"gap_{g}"] = norms_sequential(recorded[a] - recorded[b])
    assert [c.to_dict() for c in _validate(cert, _save(tmp_path, gaps, "g.npz")).checks] == ref
    lines = ["# l1_design: " + ", ".join(repr(float(v)) for v in recorded["l1_design"])]
    lines.append(f"# fingerprint: {recorded['fingerprint'].item()}")
    lines.append("scenario,path,t,x0,x1")
    for s in SCENARIOS:
        for i in range(N_PATHS):
            for k, t in enumerate(recorded["t"]):
                x = recorded[s][i, k]
                lines.append(f"{s},{i},{float(t)!r},{float(x[0])!r},{float(x[1])!r}")
    csv_path = tmp_path / "data.csv"
    csv_path.write_text("\n".join(lines) + "\n")
    assert [c.to_dict() for c in _validate(cert, csv_path).checks] == ref


def test_data_at_other_l1_parameters_do_not_validate_the_l1_bound(tmp_path, deployed, recorded):
    cert = deployed[0]
    arrays = dict(recorded, l1_design=recorded["l1_design"] * np.array([2.0, 1.0, 1.0]))
    checks = by_name(_validate(cert, _save(tmp_path, arrays)).checks)
    assert checks["policy_radius"].status == HOLDS
    assert checks["uncertainty_gap"].status == NOT_CHECKED
    assert "not at certified parameters" in checks["uncertainty_gap"].reason


def test_diverged_paths_are_unknown_not_errors(tmp_path, deployed, recorded):
    cert = deployed[0]
    arrays = dict(recorded)
    arrays["learned_true"] = arrays["learned_true"].copy()
    arrays["learned_true"][4, 5:] = np.nan
    with pytest.raises(SpecError, match="learned_true: path 4 has a non-finite value"):
        load_recorded(_save(tmp_path, arrays))
    arrays["diverged"] = np.arange(N_PATHS) == 4
    rep = _validate(cert, _save(tmp_path, arrays))
    radius = by_name(rep.checks)["policy_radius"]
    assert radius.extra["n"] == N_PATHS and radius.extra["n_unknown"] == 1


# ---------------------------------------------------------------------------- the command
def test_data_within_the_bounds_exit_0(tmp_path, capsys, recorded):
    """End to end: the command certifies the spec itself."""
    path = _save(tmp_path, recorded)
    code, out, err = run_cli(capsys, "validate", str(SPEC), "--data", str(path), "--json")
    import json

    rep = json.loads(out)
    assert code == 0, (rep["status"], err)
    assert rep["status"] == "holds"
    assert rep["simulation"]["source"] == "recorded data"
    assert rep["simulation"]["n_paths"] == N_PATHS
    statuses = {c["name"]: c["status"] for c in rep["checks"]}
    assert statuses["policy_radius"] == statuses["uncertainty_gap"] == "holds"


def test_data_violating_a_bound_exit_1(tmp_path, capsys, deployed, recorded, certified_once):
    """Push the L1 process 3 rho_L1 away from the nominal after t = 0: the mean gap's lower
    confidence bound exceeds rho_L1."""
    cert = deployed[0]
    arrays = dict(recorded)
    bad = arrays["learned_l1_true"].copy()
    bad[:, 1:, 0] += 3.0 * cert.rho_l1
    arrays["learned_l1_true"] = bad
    path = _save(tmp_path, arrays)
    code, out, _ = run_cli(capsys, "validate", str(SPEC), "--data", str(path))
    assert code == 1
    assert out.startswith("validation: VIOLATED")


def _malformed(recorded):
    nan = dict(recorded, expert_nominal=recorded["expert_nominal"].copy())
    nan["expert_nominal"][2, 3, 1] = np.nan
    unsorted = dict(recorded, t=recorded["t"][[0, 2, 1, *range(3, recorded["t"].size)]])
    unpaired = dict(recorded, learned_nominal=recorded["learned_nominal"].copy())
    unpaired["learned_nominal"][7, 0] += 0.1
    return [
        (
            "shape",
            {**recorded, "learned_true": recorded["learned_true"][:, :, 0]},
            "learned_true",
            "shape",
        ),
        (
            "times",
            {**recorded, "learned_true": recorded["learned_true"][:, :-1]},
            "learned_true",
            "times",
        ),
        (
            "paths",
            {**recorded, "learned_true": recorded["learned_true"][:-1]},
            "learned_true",
            "paths",
        ),
        ("nan", nan, "expert_nominal", "non-finite"),
        ("unsorted", unsorted, "t", "strictly increasing"),
        (
            "dimension",
            {
                k: (np.concatenate([v, v[..., :1]], axis=2) if k in SCENARIOS else v)
                for k, v in recorded.items()
            },
            "expert_nominal",
            "dimension 3",
        ),
        (
            "unknown",
            {**recorded, "learned_l1": recorded["learned_l1_true"]},
            "learned_l1",
            "unknown",
        ),
        ("unpaired", unpaired, "learned_nominal", "starts at"),
        ("horizon", {**recorded, "t": recorded["t"] * 100.0}, "t", "beyond the certified horizon"),
        ("no t", {k: v for k, v in recorded.items() if k != "t"}, "t", "missing"),
        (
            "fingerprint text",
            {**recorded, "fingerprint": np.array("policy=0123")},
            "fingerprint",
            "hex digits",
        ),
        (
            "fingerprint dtype",
            {**recorded, "fingerprint": np.arange(2.0)},
            "fingerprint",
            "one string",
        ),
    ]


def test_malformed_data_exit_2_naming_the_array_and_the_problem(tmp_path, capsys, recorded):
    for label, arrays, array, problem in _malformed(recorded):
        path = _save(tmp_path, arrays, f"{label.replace(' ', '_')}.npz")
        code, out, err = run_cli(capsys, "validate", str(SPEC), "--data", str(path))
        assert code == 2, label
        assert "Traceback" not in err and out == "", label
        assert f"{path}: {array}" in err and problem in err, (label, err)


def test_too_few_paths_for_the_confidence_exit_2(tmp_path, capsys, recorded, certified_once):
    """Three paths and 58 recorded times: the tail claim P(||X_t - x'_t|| >= kappa) <= 0.2 at
    the per-time level 1 - 0.05/58 needs N > log(0.05/58) / log(0.2) = 4.4, i.e. 5 paths."""
    few = {k: (v[:3] if k in SCENARIOS else v) for k, v in recorded.items()}
    path = _save(tmp_path, few)
    code, _, err = run_cli(capsys, "validate", str(SPEC), "--data", str(path))
    assert code == 2
    m = recorded["t"].size
    need = math.floor(math.log(0.05 / m) / math.log(0.2)) + 1
    assert "3 paths are too few" in err and f"record at least {need} paths" in err, err
    assert "learned_l1_true, learned_nominal" in err


# ------------------------------------------------------------------------- fingerprints
PENDULUM_LEARNED = 'learned = ["9.81*sin(q) - 3.96*q - 4.04*q_dot"]'
"""The certified learned policy of examples/pendulum; the tests below change one gain."""


def _certified_design(cert):
    """``(omega, lambda_s, T_s)`` and ``Theta`` (the pendulum is certified in ``z = Theta x``)."""
    d = cert.l1.design
    assert cert.coordinates is not None  # so the policy part is checked to be x's, not z's
    return (d.omega, d.lambda_s, d.Ts), cert.coordinates.theta


def _with_fingerprint(recorded, fp):
    return {**recorded, "fingerprint": np.array(str(fp))}


def test_data_of_a_changed_policy_are_refused_naming_the_policy(
    tmp_path, capsys, deployed, recorded, certified_once
):
    """The fingerprint data recorded with the spec's policy after one gain moved (3.96 ->
    3.95) carry, at the certified design: exit 1, the policy named with both digests."""
    cert = deployed[0]
    text = SPEC.read_text()
    assert PENDULUM_LEARNED in text
    changed = write_spec(
        tmp_path, text.replace(PENDULUM_LEARNED, PENDULUM_LEARNED.replace("3.96", "3.95"))
    )
    old = fingerprint_of(load_spec(changed).system, *_certified_design(cert))
    assert old.design == cert.fingerprint.design and old.policy != cert.fingerprint.policy
    path = _save(tmp_path, _with_fingerprint(recorded, old))
    code, out, err = run_cli(capsys, "validate", str(SPEC), "--data", str(path), "--json")
    assert code == 1 and out == "" and "Traceback" not in err
    assert "recorded with another policy than the certificate's" in err, err
    assert f"policy={old.policy} in the data" in err
    assert f"policy={cert.fingerprint.policy} certified" in err
    assert "design=" not in err  # the design is not blamed
    with pytest.raises(FingerprintError, match="another policy"):
        _validate(cert, path)


def test_data_of_a_changed_design_are_refused_naming_the_design(
    tmp_path, capsys, deployed, recorded, certified_once
):
    """The same data, recorded (so their fingerprint says) with twice the certified omega."""
    cert = deployed[0]
    (omega, lambda_s, ts), theta = _certified_design(cert)
    x_system = load_spec(SPEC).system
    assert design_fingerprint(x_system, (omega, lambda_s, ts), theta) == cert.fingerprint.design
    other = Fingerprint(
        policy=cert.fingerprint.policy,
        design=design_fingerprint(x_system, (2.0 * omega, lambda_s, ts), theta),
    )
    path = _save(tmp_path, _with_fingerprint(recorded, other))
    code, out, err = run_cli(capsys, "validate", str(SPEC), "--data", str(path))
    assert code == 1 and out == ""
    assert "recorded with another design than the certificate's" in err, err
    assert f"design={other.design} in the data, design={cert.fingerprint.design} certified" in err
    assert "policy=" not in err


def test_data_without_a_fingerprint_are_refused_unless_the_flag_accepts_them(
    tmp_path, capsys, recorded, certified_once
):
    bare = {k: v for k, v in recorded.items() if k != "fingerprint"}
    path = _save(tmp_path, bare)
    code, out, err = run_cli(capsys, "validate", str(SPEC), "--data", str(path))
    assert code == 1 and out == ""
    assert "refused: the data carry no fingerprint" in err and "--accept-unfingerprinted" in err
    code, out, err = run_cli(
        capsys, "validate", str(SPEC), "--data", str(path), "--accept-unfingerprinted", "--json"
    )
    import json

    rep = json.loads(out)
    assert code == 0 and rep["status"] == "holds"
    assert "warning" in err and "no fingerprint" in err
    assert any(n.startswith("WARNING: the data carry no fingerprint") for n in rep["notes"])
    assert rep["simulation"]["fingerprint"] is None
    # with a fingerprint the report says which
    code, out, _ = run_cli(
        capsys, "validate", str(SPEC), "--data", str(_save(tmp_path, recorded, "fp.npz")), "--json"
    )
    assert code == 0 and json.loads(out)["simulation"]["fingerprint"]["policy"] == (
        Fingerprint.parse(recorded["fingerprint"].item()).policy
    )


def test_the_policy_fingerprint_alone_covers_data_of_the_policy_alone(tmp_path, deployed, recorded):
    """``learned_policy(spec).fingerprint`` (no design part): enough for the nominal processes,
    refused for data that hold the L1-DRAC process."""
    cert, ctrl, policy = deployed
    assert policy.fingerprint == Fingerprint(policy=cert.fingerprint.policy)
    assert ctrl.fingerprint == cert.fingerprint
    nominal = {k: recorded[k] for k in ("t", "expert_nominal", "learned_nominal")}
    rep = _validate(cert, _save(tmp_path, _with_fingerprint(nominal, policy.fingerprint)))
    assert rep.status == HOLDS
    with pytest.raises(FingerprintError, match="no design part"):
        _validate(cert, _save(tmp_path, _with_fingerprint(recorded, policy.fingerprint), "l1.npz"))
