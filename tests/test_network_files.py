"""Network files: ONNX (built with onnx.helper as torch.onnx.export writes them), safetensors
(PyTorch nn.Sequential and Flax Dense layouts) and npz, read into the MLP value object; malformed
or unsupported files are a SpecError naming the node or tensor; export -> import is exact."""

from __future__ import annotations

import json

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")  # a declared dependency; the skip only names a broken venv
from onnx import TensorProto, helper, numpy_helper  # noqa: E402
from onnx.reference import ReferenceEvaluator  # noqa: E402
from safetensors.numpy import save_file  # noqa: E402

from drip_cert.errors import SpecError  # noqa: E402
from drip_cert.model.mlp import MLP, init_mlp  # noqa: E402
from drip_cert.model.network_files import load_network  # noqa: E402
from drip_cert.model.onnx_io import read_onnx, write_onnx  # noqa: E402

FLOAT32_AGREE = 1e-5  # float32 graph vs float64 conversion, O(1) outputs, widths <= 16
GELU_REFERENCE = 1e-7  # onnx.reference's Gelu body holds float32 constants, even in float64
FLOAT64_REFERENCE = 1e-13  # onnx.reference in float64: other summation order and libm calls
EXACT = 0.0  # float64 export -> import -> evaluate: the same operations on the same numbers
JAX_ORDER = 1e-14  # the spec evaluates blocks with jax (another summation order, MLP.apply_jax)


def _torch_like_onnx(
    path,
    ws,
    bs,
    acts,
    dtype=np.float32,
    in_scale=None,
    out_scale=None,
    extra_nodes=(),
    gelu_opset=False,
):
    """An ONNX file as torch.onnx.export writes an nn.Sequential of Linear layers: Gemm with
    transB = 1 and the weight as an (out, in) initializer, activations as their own nodes;
    optional input scaling (Mul by a constant before the first Gemm) and output scaling."""
    elem = TensorProto.FLOAT if dtype == np.float32 else TensorProto.DOUBLE
    nodes, inits = [], []
    cur = "input"
    if in_scale is not None:
        inits.append(numpy_helper.from_array(np.asarray(in_scale, dtype), "in_scale"))
        nodes.append(helper.make_node("Mul", [cur, "in_scale"], ["xs"], name="/Mul"))
        cur = "xs"
    for k, (w, b, a) in enumerate(zip(ws, bs, acts)):
        inits += [
            numpy_helper.from_array(np.asarray(w, dtype), f"{2 * k}.weight"),
            numpy_helper.from_array(np.asarray(b, dtype), f"{2 * k}.bias"),
        ]
        nodes.append(
            helper.make_node(
                "Gemm",
                [cur, f"{2 * k}.weight", f"{2 * k}.bias"],
                [f"/{2 * k}/Gemm_output_0"],
                name=f"/{2 * k}/Gemm",
                alpha=1.0,
                beta=1.0,
                transB=1,
            )
        )
        cur = f"/{2 * k}/Gemm_output_0"
        if a is not None:
            op, attrs = a if isinstance(a, tuple) else (a, {})
            nodes.append(
                helper.make_node(
                    op, [cur], [f"/{2 * k + 1}/{op}_output_0"], name=f"/{2 * k + 1}/{op}", **attrs
                )
            )
            cur = f"/{2 * k + 1}/{op}_output_0"
    nodes += list(extra_nodes)
    if out_scale is not None:
        inits.append(numpy_helper.from_array(np.asarray(out_scale, dtype), "out_scale"))
        nodes.append(helper.make_node("Mul", [cur, "out_scale"], ["ys"], name="/MulOut"))
        cur = "ys"
    nodes.append(helper.make_node("Identity", [cur], ["output"], name="/Identity"))
    graph = helper.make_graph(
        nodes,
        "main_graph",
        [helper.make_tensor_value_info("input", elem, ["batch", np.shape(ws[0])[1]])],
        [helper.make_tensor_value_info("output", elem, ["batch", np.shape(ws[-1])[0]])],
        initializer=inits,
    )
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", 20 if gelu_opset else 17)]
    )
    model.ir_version = 9 if gelu_opset else 8
    onnx.save(model, str(path))
    return path


def _weights(sizes, seed):
    rng = np.random.default_rng(seed)
    ws = [rng.normal(size=(o, i)) / np.sqrt(i) for i, o in zip(sizes[:-1], sizes[1:])]
    bs = [0.1 * rng.normal(size=o) for o in sizes[1:]]
    return ws, bs


def _reference(path, x, dtype=np.float32):
    return ReferenceEvaluator(str(path)).run(None, {"input": x.astype(dtype)})[0]


@pytest.mark.parametrize(
    "acts, specs",
    [
        (["Relu", "Relu", None], ("relu", "relu", "identity")),
        (["Sigmoid", "Tanh", None], ("sigmoid", "tanh", "identity")),
        (
            [("LeakyRelu", {"alpha": 0.2}), "Softplus", "Tanh"],
            (f"leaky_relu({float(np.float32(0.2))!r})", "softplus", "tanh"),
        ),
        ([("Elu", {"alpha": 1.0}), "Relu", None], ("elu(1.0)", "relu", "identity")),
    ],
)
def test_onnx_torch_layout_reads_and_agrees_with_onnx_reference(tmp_path, acts, specs):
    ws, bs = _weights((3, 16, 16, 2), seed=1)
    f = _torch_like_onnx(tmp_path / "p.onnx", ws, bs, acts)
    mlp = load_network(f, expect_in=3, expect_out=2)
    assert mlp.activation_specs == specs and mlp.sizes == (3, 16, 16, 2)
    x = np.random.default_rng(2).normal(size=(50, 3))
    np.testing.assert_allclose(
        mlp.apply_np(x.astype(np.float32)), _reference(f, x), atol=FLOAT32_AGREE
    )
    # the float32 weights are read exactly (float64 holds every float32)
    np.testing.assert_array_equal(mlp.weights[0], ws[0].astype(np.float32))


def test_onnx_input_and_output_scaling_fold_into_the_affine_layers(tmp_path):
    ws, bs = _weights((2, 8, 1), seed=3)
    f = _torch_like_onnx(
        tmp_path / "s.onnx", ws, bs, ["Tanh", None], in_scale=[0.5, 2.0], out_scale=[4.0]
    )
    mlp = load_network(f)
    assert len(mlp.weights) == 2  # both scalings folded: no extra layer
    x = np.random.default_rng(4).normal(size=(40, 2))
    np.testing.assert_allclose(
        mlp.apply_np(x.astype(np.float32)), _reference(f, x), atol=FLOAT32_AGREE
    )
    # powers of two: the folding is exact
    np.testing.assert_array_equal(mlp.weights[0], ws[0].astype(np.float32) * np.array([0.5, 2.0]))
    # output scaling after a nonlinearity becomes one more affine layer
    g = _torch_like_onnx(tmp_path / "t.onnx", ws, bs, ["Tanh", "Tanh"], out_scale=[3.0])
    m2 = load_network(g)
    assert m2.activation_specs == ("tanh", "tanh", "identity")
    np.testing.assert_allclose(
        m2.apply_np(x.astype(np.float32)), _reference(g, x), atol=FLOAT32_AGREE
    )


def test_onnx_gelu_and_silu_patterns(tmp_path):
    ws, bs = _weights((2, 6, 1), seed=5)
    f = _torch_like_onnx(tmp_path / "g.onnx", ws, bs, ["Gelu", None], gelu_opset=True)
    assert load_network(f).activation_specs == ("gelu", "identity")
    mlp = MLP(tuple(ws), tuple(bs), activations=("silu", "identity"))
    g = write_onnx(mlp, tmp_path / "silu.onnx")
    back = load_network(g)
    assert back.activation_specs == ("silu", "identity")
    x = np.random.default_rng(6).normal(size=(20, 2))
    np.testing.assert_array_equal(back.apply_np(x), mlp.apply_np(x))


@pytest.mark.parametrize(
    "specs",
    [
        ("relu", "relu", "identity"),
        ("tanh", "sigmoid", "tanh"),
        ("leaky_relu(0.1)", "elu(0.5)", "identity"),
        ("gelu", "softplus", "identity"),
    ],
)
def test_export_import_round_trip_is_exact_in_float64(tmp_path, specs):
    mlp = init_mlp((3, 7, 5, 2), np.random.default_rng(7))
    mlp = MLP(mlp.weights, mlp.biases, activations=specs)
    back = read_onnx(write_onnx(mlp, tmp_path / "p.onnx"))
    assert back.activation_specs == mlp.activation_specs
    for a, b in zip(mlp.weights + mlp.biases, back.weights + back.biases):
        np.testing.assert_array_equal(a, b)
    x = np.random.default_rng(8).normal(size=(30, 3))
    assert np.max(np.abs(back.apply_np(x) - mlp.apply_np(x))) == EXACT
    ref = ReferenceEvaluator(str(tmp_path / "p.onnx")).run(None, {"x": x})[0]
    tol = GELU_REFERENCE if "gelu" in specs else FLOAT64_REFERENCE
    np.testing.assert_allclose(ref, mlp.apply_np(x), rtol=tol, atol=tol)
    f32 = read_onnx(write_onnx(mlp, tmp_path / "p32.onnx", dtype="float32"))
    np.testing.assert_array_equal(f32.weights[0], mlp.weights[0].astype(np.float32))


def _bad(tmp_path, nodes, inits, name="bad.onnx"):
    graph = helper.make_graph(
        nodes,
        "g",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, ["N", 2])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, ["N", 2])],
        initializer=inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(tmp_path / name))
    return tmp_path / name


def test_unsupported_and_malformed_onnx_name_the_node(tmp_path):
    w = numpy_helper.from_array(np.eye(2, dtype=np.float32), "W")
    conv = _bad(
        tmp_path, [helper.make_node("LSTM", ["input", "W", "W"], ["output"], name="rnn0")], [w]
    )
    with pytest.raises(SpecError, match=r"rnn0.*LSTM.*not supported.*Gemm"):
        load_network(conv)
    skip = _bad(
        tmp_path,
        [
            helper.make_node("Relu", ["input"], ["h"], name="r"),
            helper.make_node("Add", ["h", "input"], ["output"], name="skip"),
        ],
        [],
        "skip.onnx",
    )
    with pytest.raises(SpecError, match=r"skip.*Add"):
        load_network(skip)
    iw = numpy_helper.from_array(np.eye(2, dtype=np.int64), "Wi")
    ints = _bad(tmp_path, [helper.make_node("MatMul", ["input", "Wi"], ["output"])], [iw], "i.onnx")
    with pytest.raises(SpecError, match=r"Wi.*int64"):
        load_network(ints)
    (tmp_path / "junk.onnx").write_bytes(b"not a protobuf at all \x00\x01")
    with pytest.raises(SpecError, match="junk.onnx"):
        load_network(tmp_path / "junk.onnx")
    ws, bs = _weights((2, 4, 2), seed=9)
    ok = _torch_like_onnx(tmp_path / "ok.onnx", ws, bs, ["Relu", None])
    with pytest.raises(SpecError, match="3 inputs|declares 3"):
        load_network(ok, expect_in=3)
    with pytest.raises(SpecError, match="own activations"):
        load_network(ok, activation="relu")


def test_a_misread_graph_fails_the_reference_check(tmp_path, monkeypatch):
    """The onnx.reference check bites: reading Gemm's transB wrongly is caught (exit 2)."""
    import drip_cert.model.onnx_io as oio

    ws, bs = _weights((3, 3, 3), seed=10)
    f = _torch_like_onnx(tmp_path / "sq.onnx", ws, bs, ["Relu", None])
    load_network(f)
    orig = oio._attrs
    monkeypatch.setattr(oio, "_attrs", lambda node: {**orig(node), "transB": 0})
    with pytest.raises(SpecError, match="differs from onnx.reference"):
        load_network(f)


@pytest.mark.parametrize("layout", ["torch", "flax", "flax_params"])
def test_safetensors_layouts(tmp_path, layout):
    ws, bs = _weights((3, 8, 8, 2), seed=11)
    t = {}
    for k, (w, b) in enumerate(zip(ws, bs)):
        if layout == "torch":
            t[f"{2 * k}.weight"], t[f"{2 * k}.bias"] = w, b
        else:
            pre = "params." if layout == "flax_params" else ""
            t[f"{pre}Dense_{k}.kernel"], t[f"{pre}Dense_{k}.bias"] = np.ascontiguousarray(w.T), b
    save_file(t, str(tmp_path / "p.safetensors"))
    mlp = load_network(tmp_path / "p.safetensors", activation="relu", expect_in=3, expect_out=2)
    assert mlp.activation_specs == ("relu", "relu", "identity")
    for a, b in zip(mlp.weights, ws):
        np.testing.assert_array_equal(a, b)
    mixed = load_network(tmp_path / "p.safetensors", activation=["tanh", "relu", "sigmoid"])
    assert mixed.activation_specs == ("tanh", "relu", "sigmoid")


def test_malformed_safetensors_name_file_and_tensor(tmp_path):
    ws, bs = _weights((3, 4, 2), seed=12)
    f = tmp_path / "m.safetensors"
    save_file({"0.weight": ws[0], "0.bias": bs[0], "2.weight": ws[1]}, str(f))
    with pytest.raises(SpecError, match=r"m.safetensors.*'2.bias' is missing"):
        load_network(f, activation="relu")
    save_file(
        {"0.weight": ws[0], "0.bias": bs[0], "2.weight": ws[1][:, :3], "2.bias": bs[1]}, str(f)
    )
    with pytest.raises(SpecError, match=r"'2.weight' takes 3 inputs"):
        load_network(f, activation="relu")
    save_file({"0.weight": ws[0].astype(np.int32), "0.bias": bs[0]}, str(f))
    with pytest.raises(SpecError, match=r"'0.weight' has dtype int32"):
        load_network(f, activation="relu")
    save_file({"0.weight": ws[0], "0.bias": bs[0], "1.running_mean": bs[0]}, str(f))
    with pytest.raises(SpecError, match="running_mean"):
        load_network(f, activation="relu")
    save_file({"0.weight": ws[0], "0.bias": bs[0]}, str(f))
    with pytest.raises(SpecError, match="no activations"):
        load_network(f)
    with pytest.raises(SpecError, match="2 activations given for 1 layers"):
        load_network(f, activation=["relu", "relu"])
    with pytest.raises(SpecError, match="extension"):
        load_network(tmp_path / "p.pt")


def test_npz_with_per_layer_activations(tmp_path):
    mlp = MLP(*_weights((2, 5, 5, 1), seed=13), activations=("relu", "tanh", "identity"))
    mlp.save(tmp_path / "n.npz")
    back = load_network(tmp_path / "n.npz")
    assert back.activation_specs == ("relu", "tanh", "identity")
    over = load_network(tmp_path / "n.npz", activation=["gelu", "gelu", "identity"])
    assert over.activation_specs == ("gelu", "gelu", "identity")


SPEC = """
[system]
name = "onnx_block"
states = ["x1", "x2"]
horizon = 1.0
[blocks.h]
kind = "mlp"
weights = "{weights}"
{extra}
[dynamics]
f = ["-x1 + h(x)[0]", "-x2 + h(x)[1]"]
g = [["1", "0"], ["0", "1"]]
[policy]
expert = ["-h(x)[0]", "-h(x)[1]"]
[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
"""


def test_spec_block_reads_onnx_with_shapes_from_the_graph_and_cli_exits_2(tmp_path, capsys):
    from drip_cert.cli import main
    from drip_cert.spec.load import load_spec

    ws, bs = _weights((2, 6, 2), seed=14)
    _torch_like_onnx(tmp_path / "h.onnx", ws, bs, ["Relu", None])
    (tmp_path / "s.toml").write_text(SPEC.format(weights="h.onnx", extra=""))
    blk = load_spec(tmp_path / "s.toml").system.blocks["h"]
    assert (blk.in_dim, blk.out_dim) == (2, 2) and blk.mlp.activation_specs == ("relu", "identity")
    (tmp_path / "bad.toml").write_text(SPEC.format(weights="h.onnx", extra="outputs = 3"))
    with pytest.raises(SpecError, match="blocks.h.weights.*declares 3|declares 3"):
        load_spec(tmp_path / "bad.toml")
    save_file(
        {"0.weight": ws[0], "0.bias": bs[0], "2.weight": ws[1]}, str(tmp_path / "h.safetensors")
    )
    (tmp_path / "st.toml").write_text(
        SPEC.format(weights="h.safetensors", extra='activation = ["relu", "identity"]')
    )
    assert main(["certify", str(tmp_path / "st.toml")]) == 2
    err = capsys.readouterr().err
    assert "'2.bias' is missing" in err and "Traceback" not in err


LEARNED_SPEC = """
[system]
name = "export"
states = ["x1", "x2"]
horizon = 1.0
[blocks.pi_il]
kind = "mlp"
weights = "{weights}"
[dynamics]
f = ["x2", "-x1"]
g = [["0"], ["1"]]
[policy]
expert = ["-x1 - x2"]
learned = ["{learned}"]
[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
"""


def test_export_policy_round_trip_is_exact(tmp_path, capsys):
    """export-policy writes the learned policy's block; re-importing it gives the same numbers,
    bit for bit (float64), and the same network as the spec evaluates."""
    from drip_cert.cli import main
    from drip_cert.spec.load import load_spec

    mlp = MLP(
        *_weights((2, 16, 16, 1), seed=15), activations=("relu", "leaky_relu(0.1)", "identity")
    )
    mlp.save(tmp_path / "p.npz")
    spec = tmp_path / "s.toml"
    spec.write_text(LEARNED_SPEC.format(weights="p.npz", learned="pi_il(x)[0]"))
    out = tmp_path / "policy.onnx"
    assert main(["export-policy", str(spec), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["block_is_policy"] and summary["activations"] == list(mlp.activation_specs)
    back = read_onnx(out)
    x = np.random.default_rng(16).normal(size=(100, 2))
    assert np.max(np.abs(back.apply_np(x) - mlp.apply_np(x))) == EXACT
    s = load_spec(spec).system
    xs = x[:5]
    np.testing.assert_allclose(
        np.asarray(s.blocks["pi_il"].evaluate_np(xs)),
        back.apply_np(xs),
        rtol=JAX_ORDER,
        atol=JAX_ORDER,
    )
    # float32 for a robot runtime; a wrapped policy is flagged
    spec.write_text(LEARNED_SPEC.format(weights="p.npz", learned="pi_il(x)[0] - 0.5*x1"))
    assert (
        main(["export-policy", str(spec), "--out", str(tmp_path / "f.onnx"), "--dtype", "float32"])
        == 0
    )
    assert "wraps the network" in capsys.readouterr().out
    assert read_onnx(tmp_path / "f.onnx").weights[0].dtype == np.float64
    spec.write_text(
        LEARNED_SPEC.format(weights="p.npz", learned="-x1").replace(
            "[blocks.pi_il]", "[blocks.unused]"
        )
    )
    assert main(["export-policy", str(spec), "--out", str(tmp_path / "g.onnx")]) == 2
    assert "0 MLP blocks" in capsys.readouterr().err


# ----------------------------------------------------- mixed layers, scaling, PRelu, GELU as Erf


def test_onnx_mixed_activations_with_input_normalisation_and_output_scaling(tmp_path):
    """A torch-like graph with a different activation on every layer, input normalisation
    ``(x - mean) / std`` (Sub, Div) before the first Gemm and output scaling ``y * s + o`` (Mul,
    Add) after the last: one MLP, one activation per layer, agreeing with onnx.reference."""
    ws, bs = _weights((3, 8, 8, 8, 2), seed=20)
    mean = np.array([0.5, -1.0, 2.0], np.float32)
    std = np.array([2.0, 0.5, 4.0], np.float32)
    scale, offset = np.array([3.0, -0.5], np.float32), np.array([0.25, 1.0], np.float32)
    inits = [
        numpy_helper.from_array(mean, "mean"),
        numpy_helper.from_array(std, "std"),
        numpy_helper.from_array(offset, "offset"),
    ]
    pre = [
        helper.make_node("Sub", ["input", "mean"], ["xc"], name="/norm/Sub"),
        helper.make_node("Div", ["xc", "std"], ["xn"], name="/norm/Div"),
    ]
    f = _torch_like_onnx(
        tmp_path / "m.onnx",
        ws,
        bs,
        ["Relu", "Sigmoid", ("LeakyRelu", {"alpha": 0.125}), None],
        out_scale=scale,
    )
    model = onnx.load(str(f))
    g = model.graph
    first = next(n for n in g.node if n.op_type == "Gemm")
    first.input[0] = "xn"
    last = next(n for n in g.node if n.name == "/MulOut")
    last.output[0] = "ys0"
    g.node.insert(list(g.node).index(last) + 1, helper.make_node("Add", ["ys0", "offset"], ["ys"]))
    for k, n in enumerate(pre):
        g.node.insert(k, n)
    g.initializer.extend(inits)
    onnx.save(model, str(f))
    mlp = load_network(f, expect_in=3, expect_out=2)
    assert mlp.activation_specs == ("relu", "sigmoid", "leaky_relu(0.125)", "identity")
    assert mlp.sizes == (3, 8, 8, 8, 2)  # the scalings are folded into the first and last layers
    x = np.random.default_rng(21).normal(size=(50, 3)) * 3.0
    np.testing.assert_allclose(
        mlp.apply_np(x.astype(np.float32)), _reference(f, x), atol=FLOAT32_AGREE
    )


def test_onnx_errors_name_the_missing_tensor_and_the_input_type(tmp_path, capsys):
    """A Gemm bias that is neither an initializer nor a Constant is named; an integer graph input
    is a SpecError (it crashed with a ValueError); ``certify`` exits 2 without a traceback."""
    from drip_cert.cli import main

    w = numpy_helper.from_array(np.eye(2, dtype=np.float32), "W")
    f = _bad(
        tmp_path, [helper.make_node("Gemm", ["input", "W", "bias0"], ["output"], name="g0")], [w]
    )
    with pytest.raises(SpecError, match=r"g0.*Gemm.*'bias0' is neither an initializer"):
        load_network(f)
    graph = helper.make_graph(
        [helper.make_node("Relu", ["input"], ["output"], name="r")],
        "g",
        [helper.make_tensor_value_info("input", TensorProto.INT64, ["N", 2])],
        [helper.make_tensor_value_info("output", TensorProto.INT64, ["N", 2])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(tmp_path / "h.onnx"))
    with pytest.raises(SpecError, match=r"input 'input' has element type INT64"):
        load_network(tmp_path / "h.onnx")
    (tmp_path / "s.toml").write_text(SPEC.format(weights="h.onnx", extra=""))
    assert main(["certify", str(tmp_path / "s.toml")]) == 2
    err = capsys.readouterr().err
    assert "INT64" in err and "Traceback" not in err


def test_onnx_constant_nodes_with_value_float(tmp_path):
    """``Constant`` nodes holding ``value_float`` / ``value_floats`` (valid ONNX, written by some
    exporters for scalings) are constants like ``value`` tensors."""
    nodes = [
        helper.make_node("Constant", [], ["c"], name="k", value_float=2.0),
        helper.make_node("Mul", ["input", "c"], ["xs"], name="m"),
        helper.make_node("Constant", [], ["o"], name="k2", value_floats=[0.5, -1.0]),
        helper.make_node("Add", ["xs", "o"], ["output"], name="a"),
    ]
    mlp = load_network(_bad(tmp_path, nodes, []))
    np.testing.assert_array_equal(mlp.weights[0], 2.0 * np.eye(2))
    np.testing.assert_array_equal(mlp.biases[0], [0.5, -1.0])


def test_onnx_prelu_with_one_slope_per_unit(tmp_path):
    """``nn.PReLU(num_parameters=n)`` exports a slope tensor of shape (n,): read as the per-unit
    PRelu activation, agreeing with onnx.reference; export -> import is exact; a slope tensor of
    another width names the node."""
    ws, bs = _weights((2, 6, 1), seed=22)
    slopes = np.array([0.0, 0.1, 0.25, 0.5, 0.01, 0.2], np.float32)
    prelu = helper.make_node("PRelu", ["/0/Gemm_output_0", "slope"], ["h"], name="/1/PRelu")
    f = _torch_like_onnx(tmp_path / "p.onnx", ws, bs, [None, None])
    model = onnx.load(str(f))
    g = model.graph
    second = [n for n in g.node if n.op_type == "Gemm"][1]
    second.input[0] = "h"
    g.node.insert(1, prelu)
    g.initializer.append(numpy_helper.from_array(slopes, "slope"))
    onnx.save(model, str(f))
    mlp = load_network(f)
    assert mlp.activations[0].slopes == tuple(float(a) for a in slopes)
    assert not mlp.smooth
    x = np.random.default_rng(23).normal(size=(200, 2)) * 2.0
    np.testing.assert_allclose(
        mlp.apply_np(x.astype(np.float32)), _reference(f, x), atol=FLOAT32_AGREE
    )
    back = read_onnx(write_onnx(mlp, tmp_path / "back.onnx"))
    assert back.activations[0] == mlp.activations[0]
    assert np.max(np.abs(back.apply_np(x) - mlp.apply_np(x))) == EXACT
    g.initializer[-1].CopyFrom(numpy_helper.from_array(slopes[:4], "slope"))
    onnx.save(model, str(f))
    with pytest.raises(SpecError, match=r"/1/PRelu.*shape \(4,\)"):
        load_network(f)


def _gelu_erf_nodes(x: str, out: str, variant: str, dtype=np.float32):
    """GELU as torch.onnx.export writes nn.GELU() below opset 20 (Constant nodes, float32 sqrt 2);
    ``variant`` "torch": ``(x * (1 + erf(x / sqrt2))) * 0.5``; "half_first":
    ``x * ((1 + erf(x * (1/sqrt2))) * 0.5)``."""

    def c(name, v):
        return helper.make_node(
            "Constant", [], [name], value=numpy_helper.from_array(np.array(v, dtype), name)
        )

    p = f"{out}_"
    if variant == "torch":
        return [
            c(p + "s", np.sqrt(2.0)),
            helper.make_node("Div", [x, p + "s"], [p + "d"], name=p + "Div"),
            helper.make_node("Erf", [p + "d"], [p + "e"], name=p + "Erf"),
            c(p + "one", 1.0),
            helper.make_node("Add", [p + "e", p + "one"], [p + "a"], name=p + "Add"),
            helper.make_node("Mul", [x, p + "a"], [p + "m"], name=p + "Mul"),
            c(p + "half", 0.5),
            helper.make_node("Mul", [p + "m", p + "half"], [out], name=p + "Mul_1"),
        ]
    return [
        c(p + "s", 1.0 / np.sqrt(2.0)),
        helper.make_node("Mul", [p + "s", x], [p + "d"], name=p + "Mul0"),
        helper.make_node("Erf", [p + "d"], [p + "e"], name=p + "Erf"),
        c(p + "one", 1.0),
        helper.make_node("Add", [p + "one", p + "e"], [p + "a"], name=p + "Add"),
        c(p + "half", 0.5),
        helper.make_node("Mul", [p + "a", p + "half"], [p + "m"], name=p + "Mul"),
        helper.make_node("Mul", [p + "m", x], [out], name=p + "Mul_1"),
    ]


@pytest.mark.parametrize("variant", ["torch", "half_first"])
def test_onnx_gelu_written_as_erf_arithmetic_is_read_as_gelu(tmp_path, variant):
    ws, bs = _weights((2, 8, 8, 1), seed=24)
    f = _torch_like_onnx(tmp_path / "g.onnx", ws, bs, [None, None, None])
    model = onnx.load(str(f))
    g = model.graph
    gemms = [n for n in g.node if n.op_type == "Gemm"]
    for k, gemm in enumerate(gemms[:2]):  # a GELU after each hidden Gemm
        act = _gelu_erf_nodes(gemm.output[0], f"/gelu{k}", variant)
        gemms[k + 1].input[0] = f"/gelu{k}"
        g.node.insert(list(g.node).index(gemm) + 1, act[0])
        for j, n in enumerate(act[1:]):
            g.node.insert(list(g.node).index(gemm) + 2 + j, n)
    onnx.save(model, str(f))
    mlp = load_network(f)
    assert mlp.activation_specs == ("gelu", "gelu", "identity")
    x = np.random.default_rng(25).normal(size=(100, 2)) * 2.0
    np.testing.assert_allclose(
        mlp.apply_np(x.astype(np.float32)), _reference(f, x), atol=FLOAT32_AGREE
    )
    # the tanh approximation's constant (or any other) is not GELU: Erf is then unsupported
    bad = next(n for n in g.node if n.op_type == "Constant")
    bad.attribute[0].t.CopyFrom(numpy_helper.from_array(np.array(1.5, np.float32), bad.output[0]))
    onnx.save(model, str(f))
    with pytest.raises(SpecError, match="not supported|Erf"):
        load_network(f)


MIXED_SPEC = """
[system]
name = "onnx_mixed"
states = ["x1", "x2"]
inputs = ["u"]
horizon = 2.0
[blocks.r]
kind = "mlp"
weights = "mixed.onnx"
[dynamics]
f = ["-3*x1 + x2", "-x1 - 3*x2"]
g = [["0"], ["1"]]
[policy]
expert = ["-x2"]
learned = ["-x2 + r(x)[0]"]
[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
"""


@pytest.mark.slow  # certify with demonstrations and TaSIL forms: 75-100 s each, 2 loaded cores
@pytest.mark.parametrize(
    "acts", [["Tanh", "Sigmoid", None], [("LeakyRelu", {"alpha": 0.125}), "Tanh", None]]
)
def test_a_mixed_onnx_network_with_scaling_is_certified_end_to_end(tmp_path, capsys, acts):
    """A torch-layout ONNX network with a different activation per layer, input scaling and
    output scaling, as the residual of a policy on a contracting plant: certified end to end
    (smooth: the lemma route; with a leaky relu: the comparison and uniform forms)."""
    from drip_cert.cli import main

    ws, bs = _weights((2, 8, 8, 1), seed=30)
    ws = [0.5 * w for w in ws]  # a small residual: Lip(r) well below the plant's rate 3
    _torch_like_onnx(tmp_path / "mixed.onnx", ws, bs, acts, in_scale=[0.5, 2.0], out_scale=[0.25])
    (tmp_path / "s.toml").write_text(MIXED_SPEC)
    assert main(["certify", str(tmp_path / "s.toml"), "--json"]) == 0
    cert = json.loads(capsys.readouterr().out)
    assert cert["verdict"] == "certified"
    assert cert["parts"]["contraction"]["verdict"] == "certified"
    assert cert["parts"]["tasil"]["verdict"] == "certified"
    assert cert["contraction"]["learned"]["scope"]["box"] is None  # a global rate
