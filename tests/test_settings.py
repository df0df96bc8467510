"""Settings tables: every table of a spec is validated when the spec is loaded, so that
``drip-cert check-spec`` rejects each bad value and unknown key (exit 2, the file, ``table.key``,
the value and the fix, no traceback); each settings class has one set of documented defaults."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import pytest

from drip_cert.errors import SpecError
from drip_cert.spec import load_spec
from drip_cert.spec.settings import (
    CONSTANT_NAMES,
    ConstantsTable,
    ContractionSettings,
    L1Settings,
    Settings,
    SimSettings,
    TasilSettings,
)
from tests.helpers import EXAMPLES, ROOT, run_cli, two_state_spec, write_spec

BASE = two_state_spec("settings-test", uncertainty=False)
"""A valid spec without settings tables; each test appends the table it checks."""


def write(tmp_path, extra: str) -> Path:
    return write_spec(tmp_path, BASE + "\n" + extra + "\n")


def check_spec(capsys, path) -> tuple[int, str, str]:
    return run_cli(capsys, "check-spec", str(path))


# (settings text, field as written, fragments the message must contain)
BAD = [
    # [l1drac]
    ("[l1drac]\np = -3", "l1drac.p", ["p = -3", "positive integer", "p = 1 (the default)"]),
    ("[l1drac]\np = 1.5", "l1drac.p", ["p = 1.5", "positive integer"]),
    ("[l1drac]\np = 0", "l1drac.p", ["p = 0", "positive integer"]),
    ("[l1drac]\np = true", "l1drac.p", ["p = true", "positive integer"]),
    ("[l1drac]\np = 2\np_star = 1", "l1drac.p_star", ["p_star = 1", "integer >= p = 2"]),
    ("[l1drac]\np_star = 1.0", "l1drac.p_star", ["p_star = 1.0", "integer >= p = 1"]),
    ("[l1drac]\nlambda_s = -10.0", "l1drac.lambda_s", ["lambda_s = -10.0", "> 0"]),
    ("[l1drac]\nomega = 0", "l1drac.omega", ["omega = 0", "> 0"]),
    ("[l1drac]\nTs = nan", "l1drac.Ts", ["Ts = nan", "finite number > 0"]),
    ("[l1drac]\nTs = inf", "l1drac.Ts", ["Ts = inf", "finite number > 0"]),
    ("[l1drac]\nrho_a = true", "l1drac.rho_a", ["rho_a = true", "finite number > 0"]),
    ("[l1drac]\ndelta = 0.0", "l1drac.delta", ["delta = 0.0", "(0, 1)"]),
    ("[l1drac]\ndelta = 1.5", "l1drac.delta", ["delta = 1.5", "(0, 1)"]),
    ("[l1drac]\nalpha = -0.1", "l1drac.alpha", ["alpha = -0.1", ">= 0"]),
    ("[l1drac]\neps_r = 0.0", "l1drac.eps_r", ["eps_r = 0.0", "eps_r = 0.001 (the default)"]),
    ("[l1drac]\nlip_f = 1", "l1drac.lip_f", ["lip_f = 1", "true or false"]),
    ("[l1drac]\nDelta_star = 3.0", "l1drac.Delta_star", ["give it in [constants]"]),
    ("[l1drac]\npp = 2", "l1drac.pp", ["unknown key pp", "Did you mean p", "Allowed keys"]),
    # [simulation]
    ("[simulation]\ndt = -1", "simulation.dt", ["dt = -1", "> 0", "dt = 0.001 (the default)"]),
    ('[simulation]\ndt = "x"', "simulation.dt", ['dt = "x"', "finite number > 0"]),
    ("[simulation]\ndt = inf", "simulation.dt", ["dt = inf", "finite"]),
    ("[simulation]\nomega = nan", "simulation.omega", ["omega = nan", "finite"]),
    ("[simulation]\npaths = 0", "simulation.paths", ["paths = 0", "positive integer"]),
    ("[simulation]\npaths = true", "simulation.paths", ["paths = true", "positive integer"]),
    ("[simulation]\npaths = 10.0", "simulation.paths", ["paths = 10.0", "positive integer"]),
    ("[simulation]\nrecord_every = -2", "simulation.record_every", ["record_every = -2"]),
    ("[simulation]\nd_t = 0.1", "simulation.d_t", ["unknown key d_t", "Did you mean dt"]),
    # [tasil]
    ('[tasil]\nheldout = "20"', "tasil.heldout", ['heldout = "20"', "integer >= 0"]),
    ("[tasil]\nheldout = -1", "tasil.heldout", ["heldout = -1"]),
    ("[tasil]\ntrajectories = 0", "tasil.trajectories", ["trajectories = 0", "positive"]),
    ("[tasil]\nsamples = 2.5", "tasil.samples", ["samples = 2.5", "positive integer"]),
    ("[tasil]\nsteps = false", "tasil.steps", ["steps = false", "positive integer"]),
    ("[tasil]\norder = 3", "tasil.order", ["order = 3", "one of 1, 2"]),
    ("[tasil]\norder = true", "tasil.order", ["order = true", "one of 1, 2"]),
    (
        '[tasil]\nmethod = "dagr"',
        "tasil.method",
        ['method = "dagr"', '"tasil", "bc", "dagger", "dart"'],
    ),
    ('[tasil]\nactivation = "relu"', "tasil.activation", ['"relu"', '"tanh", "gelu"']),
    ("[tasil]\nhidden = [64, 0]", "tasil.hidden", ["hidden = [64, 0]", "positive integers"]),
    ("[tasil]\nhidden = []", "tasil.hidden", ["hidden = []"]),
    ("[tasil]\ndelta = 1.0", "tasil.delta", ["delta = 1.0", "(0, 1)"]),
    ("[tasil]\nlr = inf", "tasil.lr", ["lr = inf", "finite number > 0"]),
    ("[tasil]\neta = nan", "tasil.eta", ["eta = nan", "inf allowed"]),
    ("[tasil]\ntube_radius = -inf", "tasil.tube_radius", ["tube_radius = -inf"]),
    ("[tasil]\nseed = 1.5", "tasil.seed", ["seed = 1.5", "an integer"]),
    ("[tasil]\npolicy = 3", "tasil.policy", ["policy = 3", "string"]),
    ("[tasil]\ntrajectorys = 3", "tasil.trajectorys", ["Did you mean trajectories"]),
    # [contraction]
    ('[contraction]\nmethod = "exact"', "contraction.method", ['"exact"', '"interval-bnb"']),
    # a message quotes a number as the spec writes it (its literal text), not its float repr
    ("[contraction]\ntol = -1e-3", "contraction.tol", ["tol = -1e-3", "> 0"]),
    ("[contraction]\ntol = nan", "contraction.tol", ["tol = nan", "finite"]),
    ("[contraction]\nmax_boxes = 0", "contraction.max_boxes", ["max_boxes = 0", "positive"]),
    ("[contraction]\nmax_boxes = 1e3", "contraction.max_boxes", ["max_boxes = 1e3"]),
    ("[contraction]\nmetric = 1", "contraction.metric", ["metric = 1", '"euclidean", "lmi"']),
    (
        "[contraction]\nmetric = [[1.0, 2.0], [2.0, 1.0]]",
        "contraction.metric",
        ["positive definite"],
    ),
    ("[contraction]\nmetric = [[1.0, 0.5], [0.4, 1.0]]", "contraction.metric", ["symmetric"]),
    ('[contraction]\nmetric = "lmii"', "contraction.metric", ['"lmi"']),
    ("[contraction]\nmax_time = 0", "contraction.max_time", ["max_time = 0", "> 0"]),
    ("[contraction]\nmax_time = nan", "contraction.max_time", ["max_time = nan"]),
    ("[contraction]\nregion = [[-2, 2]]", "contraction.region", ["2 pairs [lo, hi]"]),
    ("[contraction]\nregion = [[-2, 2], [-2]]", "contraction.region", ["not a pair"]),
    ("[contraction]\nregion = [[-2, 2], [2, -2]]", "contraction.region", ["is empty"]),
    ("[contraction]\nregion = [[-2, 2], [-2, inf]]", "contraction.region", ["not a finite"]),
    ("[contraction]\nregion = [[-2, 2], [-2, nan]]", "contraction.region", ["not a finite"]),
    ("[contraction]\nregion = [[-2, 2], [true, 2]]", "contraction.region", ["not a finite"]),
    ("[contraction]\nregion = [[0, 0.5], [-1, 1]]", "contraction.region", ["contain the support"]),
    ("[contraction]\nregion = 3", "contraction.region", ["region = 3"]),
    ('[contraction]\nmethdo = "auto"', "contraction.methdo", ["Did you mean method"]),
    # [constants]
    ("[constants]\nL_muu = 0.1", "constants.L_muu", ["L_muu (= 0.1)", "Did you mean L_mu"]),
    ("[constants]\nL_mu = -0.1", "constants.L_mu", ["L_mu = -0.1", ">= 0"]),
    ("[constants]\nL_mu = nan", "constants.L_mu", ["L_mu = nan", "finite"]),
    ("[constants]\nDelta_f = inf", "constants.Delta_f", ["Delta_f = inf", "finite"]),
    ("[constants]\nL_mu = true", "constants.L_mu", ["L_mu = true"]),
    ('[constants]\nL_mu = "0.1"', "constants.L_mu", ['L_mu = "0.1"']),
    ("[constants]\nlambda = 0.0", "constants.lambda", ["lambda = 0.0", "> 0"]),
    ("[constants]\neps_r = 0", "constants.eps_r", ["eps_r = 0", "> 0"]),
    ("[constants]\np_star = 3", "constants.p_star", ["give it in [l1drac]"]),
    ("[constants]\nm = 1", "constants.m", ["columns of [dynamics] g"]),
    ("[constants]\ngamma0 = 1.0", "constants.gamma0", ["unknown key gamma0", "Allowed keys"]),
]


@pytest.mark.parametrize("text, field, fragments", BAD, ids=[b[1] + ":" + b[0] for b in BAD])
def test_check_spec_rejects_bad_settings(tmp_path, capsys, text, field, fragments):
    p = write(tmp_path, text)
    code, out, err = check_spec(capsys, p)
    assert code == 2, err
    assert out == ""
    assert "Traceback" not in err
    assert f"{p}: {field}: " in err, err
    for frag in fragments:
        assert frag in err, (frag, err)


def test_error_is_spec_error_with_path_and_field(tmp_path):
    p = write(tmp_path, "[simulation]\ndt = -1")
    with pytest.raises(SpecError) as e:
        load_spec(p)
    assert e.value.field == "simulation.dt" and e.value.path == str(p)
    assert isinstance(e.value, ValueError)


@pytest.mark.parametrize("table", ["contraction", "l1drac", "tasil", "simulation", "constants"])
def test_unknown_key_in_every_table(tmp_path, capsys, table):
    p = write(tmp_path, f"[{table}]\nbogus_key = 1")
    code, _, err = check_spec(capsys, p)
    assert code == 2 and f"{table}.bogus_key" in err and "unknown key bogus_key" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("table", ["contraction", "l1drac", "tasil", "simulation", "constants"])
def test_table_that_is_not_a_table(tmp_path, capsys, table):
    p = write_spec(tmp_path, f"{table} = 3\n" + BASE)
    code, _, err = check_spec(capsys, p)
    assert code == 2 and str(p) in err and "Traceback" not in err


# ------------------------------------------------------------------ defaults
def test_documented_defaults():
    """The values documented in the README and in the classes' docstrings."""
    c = ContractionSettings()
    assert (c.method, c.region, c.tol, c.max_boxes, c.metric, c.max_time) == (
        "auto",
        None,
        1e-3,
        4000,
        True,
        math.inf,  # no wall-time guard: the box count is the budget (same certificate anywhere)
    )
    l1 = L1Settings()
    assert (l1.p, l1.p_star, l1.eps_r, l1.eps_a) == (1, 1, 1e-3, 1e-3)
    assert all(
        getattr(l1, k) is None
        for k in ("lambda_s", "omega", "Ts", "rho_r", "rho_a", "delta", "alpha", "lip_f")
    )
    assert L1Settings(p=3).p_star == 3
    t = TasilSettings()
    # heldout: the smallest count at which the held-out form can pass at delta = 0.1 (59)
    assert (t.method, t.order, t.trajectories, t.heldout, t.samples) == ("tasil", 1, 20, 59, 100)
    assert (t.hidden, t.activation, t.steps, t.lr, t.batch, t.seed) == (
        (64, 64),
        "tanh",
        2000,
        3e-3,
        128,
        0,
    )
    assert t.delta == 0.1 and t.eta == math.inf and t.tube_radius == math.inf
    assert t.policy is None
    s = SimSettings()
    assert (s.dt, s.paths, s.chunk_size, s.omega, s.lambda_s, s.Ts, s.record_every) == (
        1e-3,
        1000,
        2048,
        50.0,
        10.0,
        0.01,
        10,
    )
    assert dict(ConstantsTable().values) == {}


def test_absent_tables_give_the_defaults(tmp_path):
    spec = load_spec(write(tmp_path, ""))
    st = spec.settings
    assert st == Settings(present=frozenset())
    assert st.contraction == ContractionSettings() and st.simulation == SimSettings()
    assert st.tasil == TasilSettings() and st.l1drac == L1Settings()


def test_written_values_are_typed(tmp_path):
    spec = load_spec(
        write(
            tmp_path,
            "[contraction]\nregion = [[-2, 2], [-1, 1.5]]\ntol = 1\nmax_time = inf\n"
            "[l1drac]\np = 2\np_star = 4\nlambda_s = 10\ndelta = 0.05\nalpha = 0\nlip_f = false\n"
            "[tasil]\nheldout = 0\nhidden = [8]\neta = inf\n"
            "[simulation]\ndt = 1\npaths = 7\n"
            "[constants]\nL_mu = 0\nlambda = 2\n",
        )
    )
    st = spec.settings
    assert st.contraction.region == ((-2.0, 2.0), (-1.0, 1.5))
    assert isinstance(st.contraction.tol, float) and st.contraction.max_time == math.inf
    assert (st.l1drac.p, st.l1drac.p_star, st.l1drac.lambda_s) == (2, 4, 10.0)
    assert isinstance(st.l1drac.lambda_s, float) and st.l1drac.lip_f is False
    assert st.l1drac.alpha == 0.0 and st.l1drac.given == {
        "p",
        "p_star",
        "lambda_s",
        "delta",
        "alpha",
        "lip_f",
    }
    assert (st.tasil.heldout, st.tasil.hidden) == (0, (8,))
    assert isinstance(st.simulation.dt, float) and st.simulation.paths == 7
    assert dict(st.constants.values) == {"L_mu": 0.0, "lambda": 2.0}
    assert st.present == {"contraction", "l1drac", "tasil", "simulation", "constants"}
    import dataclasses

    # one source of truth: the settings (raw tables are a construction input, never stored)
    assert "tables" not in {f.name for f in dataclasses.fields(spec)}
    assert not hasattr(spec, "table")


def test_spec_rebuilt_from_tables_and_with_system(tmp_path):
    from drip_cert.spec.load import Spec

    spec = load_spec(write(tmp_path, "[simulation]\npaths = 7"))
    again = Spec(spec.path, spec.system, {"simulation": {"paths": 7}})
    assert again.settings == spec.settings
    assert spec.with_system(spec.system).settings is spec.settings
    with pytest.raises(SpecError, match="simulation.dt"):
        Spec(spec.path, spec.system, {"simulation": {"dt": -1}})
    with pytest.raises(SpecError, match="either settings or tables"):
        Spec(spec.path, spec.system, {"simulation": {"paths": 7}}, spec.settings)


def test_spec_in_coordinates_maps_the_system_and_the_region(tmp_path):
    """``Spec.in_coordinates(Theta)``: the z-system is the exact transform, the contraction
    region the box enclosing the image of the x-region, the analysis in z as it is."""
    import numpy as np

    spec = load_spec(write(tmp_path, '[contraction]\nregion = [[-2, 2], [-3, 3]]\nmetric = "auto"'))
    theta = np.array([[2.0, 0.0], [1.0, 1.0]])
    z = spec.in_coordinates(theta)
    assert z.settings.contraction.region == ((-4.0, 4.0), (-5.0, 5.0))  # |2x1|, |x1 + x2|
    assert z.settings.contraction.coordinates == "euclidean" and not z.settings.contraction.metric
    assert z.settings.tasil == spec.settings.tasil and z.path == spec.path
    assert z.system.support == ((-2.0, 2.0), (-2.0, 2.0))  # support [-1, 1]^2 mapped


# ------------------------------------------------------------------ valid specs
EXAMPLE_SPECS = sorted(
    p.relative_to(ROOT).as_posix()
    for p in EXAMPLES.glob("*/*.toml")
    if p.parent.name != "l1drac_constants"
)  # l1drac_constants holds a design-l1 constants file, not a spec


@pytest.mark.parametrize("path", EXAMPLE_SPECS)
def test_examples_pass_check_spec(capsys, path):
    code, out, err = check_spec(capsys, ROOT / path)
    assert code == 0, err
    assert "OK" in out


def test_readme_settings_tables_are_valid(tmp_path):
    """The settings tables of the spec example of docs/getting_started.md load."""
    text = (ROOT / "docs" / "getting_started.md").read_text()
    block = text[text.index("[constants]                    # optional") :]
    block = block[: block.index("```")]
    spec = load_spec(write(tmp_path, block))
    assert spec.settings.constants.values == {"L_mu": 0.1}
    assert spec.settings.l1drac.lambda_s == 10.0


# ------------------------------------------------------------------ one list of constants
def test_constant_names_are_the_l1drac_real_constants():
    from drip_cert.bounds.l1drac.constants import _REAL_FIELDS

    assert CONSTANT_NAMES == tuple(n for n, _ in _REAL_FIELDS)


def test_uncertainty_constants_validates_a_plain_mapping(tmp_path):
    from drip_cert.analysis.growth.constants import uncertainty_constants

    s = load_spec(write(tmp_path, "")).system
    with pytest.raises(SpecError, match=r"constants\.L_muu.*Did you mean L_mu"):
        uncertainty_constants(s, {"L_muu": 0.1})
    with pytest.raises(SpecError, match=r"constants\.L_mu"):
        uncertainty_constants(s, {"L_mu": -1.0})


def test_settings_module_is_in_the_spec_layer():
    """drip_cert.spec.settings imports only errors, provenance, vocabulary, numerics and the
    literal type of model (a number keeps the text it was written with, in messages too)."""
    tree = ast.parse((ROOT / "drip_cert" / "spec" / "settings.py").read_text())
    mods = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            mods.add(node.module)
        elif isinstance(node, ast.Import):
            mods.update(a.name for a in node.names)
    ours = {m for m in mods if m.startswith("drip_cert")}
    numerics = {"drip_cert.numerics.rounding", "drip_cert.numerics.stats"}
    layer1 = {"drip_cert.errors", "drip_cert.provenance", "drip_cert.vocabulary"}
    assert ours <= {*layer1, *numerics, "drip_cert.model.literals"}, ours


# ------------------------------------------------------------------ each setting declared once
def test_overrides_are_validated_like_the_spec():
    """A value set from Python (``dataclasses.replace`` of run_pipeline's overrides, keywords) is
    checked by the same reader as the TOML value, with the same message."""
    import dataclasses

    from drip_cert.spec.settings import L1Settings, SimSettings, TasilSettings

    with pytest.raises(SpecError, match=r"steps = -1 is not allowed.*positive integer"):
        dataclasses.replace(TasilSettings(), steps=-1)
    with pytest.raises(SpecError, match=r"dt"):
        SimSettings(dt=0.0)
    with pytest.raises(SpecError, match=r"p_star = 1 is not allowed.*>= p = 2"):
        L1Settings(p=2, p_star=1)
    with pytest.raises(SpecError, match=r"region"):
        ContractionSettings(region=((1.0, 0.0),))
    assert dataclasses.replace(TasilSettings(), steps=5).steps == 5  # a valid override passes


def test_a_new_setting_is_one_declaration():
    """A field declared with ``setting(...)`` is a key of its table (with its meaning), is read
    from TOML with its reader and default, and is checked when set from Python: nothing else to
    write."""
    import dataclasses

    from drip_cert.spec.settings import (
        TableReader,
        positive_int,
        read_declared,
        setting,
        table_keys,
        validate_declared,
    )

    @dataclasses.dataclass(frozen=True)
    class Demo:
        widgets: int = setting(3, "number of widgets", positive_int)

        def __post_init__(self) -> None:
            validate_declared(self, "demo")

    keys = table_keys(Demo)
    assert dict(keys) == {"widgets": "number of widgets"}
    assert read_declared(Demo, TableReader("demo", {}, keys)) == {"widgets": 3}
    assert read_declared(Demo, TableReader("demo", {"widgets": 7}, keys)) == {"widgets": 7}
    with pytest.raises(SpecError, match=r"demo\.widgets.*widgets \(number of widgets\)"):
        read_declared(Demo, TableReader("demo", {"widgets": 0}, keys))
    with pytest.raises(SpecError, match=r"Did you mean widgets"):
        TableReader("demo", {"widget": 1}, keys)
    with pytest.raises(SpecError, match=r"widgets"):
        Demo(widgets=-2)


def test_design_request_uses_the_declared_readers():
    """``DesignRequest`` (the designer's Python input) checks the keys it shares with
    ``[l1drac]`` by the same declared readers, so both say the same thing for the same value."""
    from drip_cert.bounds.l1drac.request import DesignRequest

    with pytest.raises(SpecError) as spec_err:
        L1Settings(delta=1.5)
    with pytest.raises(SpecError) as req_err:
        DesignRequest(p=1, delta=1.5)
    assert str(spec_err.value).split(": ", 1)[1] == str(req_err.value).split(": ", 1)[1]
    with pytest.raises(SpecError, match=r"design\.p.*positive integer"):
        DesignRequest(p=True)  # a boolean is not a moment order
