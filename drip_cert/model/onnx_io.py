"""ONNX networks in and out: a feed-forward graph becomes the :class:`~drip_cert.model.mlp.MLP`
value object, and an MLP is written as the graph a PyTorch export writes.

Reading (:func:`read_onnx`). The graph must be one chain from its single input to its single
output of

* affine nodes: ``Gemm`` (``transA = 0``; ``transB``, ``alpha``, ``beta``), ``MatMul`` by a
  constant matrix, ``Add`` / ``Sub`` / ``Mul`` / ``Div`` by a constant (scalar or per feature:
  input and output scaling);
* element-wise activations: ``Relu``, ``LeakyRelu``, ``PRelu`` (one shared slope, or one per
  unit: a slope tensor of the layer width), ``Sigmoid``, ``Tanh``, ``Softplus``, ``Elu``,
  ``Gelu`` (``approximate = "none"``), ``Identity``, ``x * Sigmoid(x)`` (SiLU, as PyTorch
  writes ``nn.SiLU``) and ``x * 0.5 * (1 + Erf(x / sqrt 2))`` (GELU as PyTorch writes
  ``nn.GELU()`` below opset 20; the constants must equal ``sqrt 2``, ``1``, ``1/2`` up to
  float32 rounding, and the graph is then read as the exact GELU, which the reference check
  below confirms);

with constants from initializers or ``Constant`` nodes. Consecutive affine nodes are composed into
one layer (in float64: exact for the shapes people use up to rounding, which the check below
bounds); an activation closes a layer; an activation with no affine node before it gets the
identity layer (exact). Anything else (``Conv``, ``LSTM``, ``If``, ``Loop``, ``Reshape``, a second
use of a data tensor, ...) is a :class:`~drip_cert.errors.SpecError` naming the node, its op type
and what is supported.

Check on load (:func:`check_against_reference`): the converted network is evaluated against
``onnx.reference.ReferenceEvaluator`` on seeded random inputs. The two differ by the rounding of
the graph's own arithmetic (often float32) and of the float64 folding; both are bounded by
``REFERENCE_ULPS * eps(dtype) * sum_k fan_in_k`` times the magnitude of the outputs (a dot product
of ``n`` terms is within ``gamma_n`` of exact, layer errors add up through slopes of at most ~1),
so a difference above that is a conversion error (wrong transposition, ignored attribute) and
the file is refused.

Writing (:func:`write_onnx`): ``Gemm`` with ``transB = 1`` and the weights as ``(out, in)``
initializers, one activation node per layer, input ``x`` of shape ``(N, in)``, output ``y``;
float64 (exact round trip) or float32 (what a robot runtime expects). ONNX float attributes are
float32, so a leaky relu slope that is not a float32 number is written as ``PRelu`` with a
tensor slope, and an elu alpha must be a float32 number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper
from onnx.reference import ReferenceEvaluator

from drip_cert.errors import SpecError
from drip_cert.model.activations import (
    Activation,
    Elu,
    Gelu,
    Identity,
    LeakyRelu,
    PRelu,
    Relu,
    Sigmoid,
    Silu,
    Softplus,
    Tanh,
)
from drip_cert.model.mlp import MLP
from drip_cert.numerics.user_files import input_file, reading

__all__ = ["REFERENCE_ULPS", "SUPPORTED_OPS", "check_against_reference", "read_onnx", "write_onnx"]

_AFFINE_OPS = ("Gemm", "MatMul", "Add", "Sub", "Mul", "Div")
_ACT_OPS = ("Relu", "LeakyRelu", "PRelu", "Sigmoid", "Tanh", "Softplus", "Elu", "Gelu", "Identity")
SUPPORTED_OPS = (*_AFFINE_OPS, *_ACT_OPS, "Constant")
"""The ONNX op types :func:`read_onnx` converts."""
REFERENCE_ULPS = 64
"""Factor of ``eps(dtype) * sum fan_in`` in the agreement tolerance with onnx.reference: the
rounding of a depth-``L`` chain of dot products is ``<= sum_k gamma_{fan_in_k}`` relative to the
magnitudes; 64 covers the float64 folding, activation library errors and summation order."""
N_CHECK = 64  # random inputs of the reference check
CHECK_SEED = 20231  # their seed (the check is a function of the file)
_OPSET = 17  # Gemm/activations; Gelu needs 20
_GELU_OPSET = 20
_CONST_ULPS = 4  # a pattern constant (sqrt 2, 1/2, 1) may differ from its value by float32 rounding


def _err(path: Path, msg: str, fld: str | None) -> SpecError:
    return SpecError(f"ONNX file {str(path)!r}: {msg}", field=fld)


@dataclass
class _Chain:
    """The layers read so far and the affine map pending since the last activation."""

    n_in: int
    layers: list[tuple[np.ndarray, np.ndarray, Activation]] = field(default_factory=list)
    W: np.ndarray | None = None  # pending affine x -> W x + b on the last activated tensor
    b: np.ndarray | None = None

    def dim(self) -> int:
        if self.W is not None:
            return int(self.W.shape[0])
        return int(self.layers[-1][0].shape[0]) if self.layers else self.n_in

    def pending(self) -> tuple[np.ndarray, np.ndarray]:
        if self.W is None or self.b is None:
            n = self.dim()
            return np.eye(n), np.zeros(n)
        return self.W, self.b

    def affine(self, W: np.ndarray, b: np.ndarray) -> None:
        """Compose ``z -> W z + b`` after the pending map."""
        W0, b0 = self.pending()
        self.W, self.b = W @ W0, W @ b0 + b

    def activate(self, act: Activation) -> None:
        W, b = self.pending()
        self.layers.append((W, b, act))
        self.W = self.b = None

    def finish(self) -> list[tuple[np.ndarray, np.ndarray, Activation]]:
        if self.W is not None or not self.layers:
            self.activate(Identity())
        return self.layers


def _vector(c: np.ndarray, n: int, what: str, path: Path, fld: str | None) -> np.ndarray:
    """A constant broadcast against ``(N, n)`` as a length-``n`` vector."""
    c = np.asarray(c, dtype=np.float64)
    if c.size == 1:
        return np.full(n, float(c.reshape(-1)[0]))
    if c.shape in ((n,), (1, n)):
        return c.reshape(n)
    raise _err(path, f"{what}: constant of shape {c.shape} does not broadcast to ({n},)", fld)


def _float_array(t, path: Path, fld: str | None) -> np.ndarray:
    a = numpy_helper.to_array(t)
    if not np.issubdtype(a.dtype, np.floating):
        raise _err(path, f"tensor {t.name!r} has dtype {a.dtype}; only float tensors", fld)
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise _err(path, f"tensor {t.name!r} contains NaN or inf", fld)
    return a


def _attrs(node) -> dict[str, Any]:
    out = {}
    for a in node.attribute:
        v = helper.get_attribute_value(a)
        out[a.name] = v.decode() if isinstance(v, bytes) else v
    return out


def _activation(node, attrs: dict[str, Any], path: Path, fld: str | None) -> Activation:
    op = node.op_type
    if op == "Relu":
        return Relu()
    if op == "LeakyRelu":
        return LeakyRelu(float(attrs.get("alpha", 0.01)))
    if op == "Sigmoid":
        return Sigmoid()
    if op == "Tanh":
        return Tanh()
    if op == "Softplus":
        return Softplus()
    if op == "Elu":
        return Elu(float(attrs.get("alpha", 1.0)))
    if op == "Gelu":
        if attrs.get("approximate", "none") != "none":
            raise _err(
                path,
                f"node {node.name!r} (Gelu) uses approximate={attrs['approximate']!r}; only "
                "the exact (erf) GELU is supported",
                fld,
            )
        return Gelu()
    raise AssertionError(op)  # pragma: no cover - _ACT_OPS is exhaustive


def read_onnx(
    path: str | Path,
    expect_in: int | None = None,
    expect_out: int | None = None,
    field: str | None = None,
    check: bool = True,
) -> MLP:
    """Convert the ONNX network ``path`` to an :class:`MLP` (see the module docstring).

    ``expect_in`` / ``expect_out`` (the block table's ``inputs`` / ``outputs``, optional) are
    checked against the graph. With ``check`` the result is compared with
    ``onnx.reference`` (:func:`check_against_reference`). Every problem is a
    :class:`~drip_cert.errors.SpecError` naming the file (exit status 2).
    """
    p = input_file(path, "ONNX file", field=field)
    with reading(p, "ONNX file"):
        try:
            model = onnx.load(str(p))
        except Exception as exc:  # protobuf raises DecodeError and others
            msg = f"cannot be parsed as ONNX ({type(exc).__name__}: {exc})"
            raise _err(p, msg, field) from exc
    mlp = _convert(model, p, field)
    for what, want, got in (
        ("inputs", expect_in, mlp.in_dim),
        ("outputs", expect_out, mlp.out_dim),
    ):
        if want is not None and want != got:
            raise _err(p, f"the graph has {got} {what} but the block declares {want}", field)
    if check:
        check_against_reference(model, mlp, p, field)
    return mlp


def _convert(model, path: Path, fld: str | None) -> MLP:
    g = model.graph
    consts = {t.name: _float_array(t, path, fld) for t in g.initializer}
    inputs = [i for i in g.input if i.name not in consts]
    if len(inputs) != 1 or len(g.output) != 1:
        raise _err(
            path,
            f"the graph has {len(inputs)} inputs and {len(g.output)} outputs; a policy has one "
            "of each",
            fld,
        )
    dims = inputs[0].type.tensor_type.shape.dim
    if not dims or not dims[-1].HasField("dim_value"):
        raise _err(path, f"input {inputs[0].name!r} has no fixed feature dimension", fld)
    elem = inputs[0].type.tensor_type.elem_type
    if not np.issubdtype(np.dtype(helper.tensor_dtype_to_np_dtype(elem)), np.floating):
        raise _err(
            path,
            f"input {inputs[0].name!r} has element type "
            f"{TensorProto.DataType.Name(elem)}; a policy takes a float tensor",
            fld,
        )
    chain = _Chain(int(dims[-1].dim_value))
    data = inputs[0].name
    consumers: dict[str, list] = {}
    for node in g.node:
        for name in node.input:
            consumers.setdefault(name, []).append(node)
    for k, node in enumerate(g.node):  # constants first: a pattern may look ahead at them
        if node.op_type == "Constant":
            where = f"node {node.name or '#' + str(k)!r} (op type Constant)"
            consts[node.output[0]] = _constant(_attrs(node), where, path, fld)
    skip: set[int] = set()
    for k, node in enumerate(g.node):
        if k in skip:
            continue
        op, attrs = node.op_type, _attrs(node)
        where = f"node {node.name or '#' + str(k)!r} (op type {op})"
        if op == "Constant":
            continue
        if op not in SUPPORTED_OPS:
            raise _err(
                path,
                f"{where} is not supported; a policy graph may use {', '.join(SUPPORTED_OPS)} "
                "(a feed-forward chain of affine layers and element-wise activations)",
                fld,
            )
        ins = [i for i in node.input if i]
        if data not in ins:
            raise _err(
                path,
                f"{where} does not act on the network's data path ({data!r}); constant "
                "sub-graphs are not supported: fold them into initializers",
                fld,
            )
        others = [i for i in ins if i != data]
        missing = [o for o in others if o not in consts]
        if missing:
            raise _err(
                path,
                f"{where}: input tensor {missing[0]!r} is neither an initializer nor the output "
                "of a Constant node; every input but the data tensor must be a constant",
                fld,
            )
        if ins.count(data) != 1 or (op in _ACT_OPS and op != "PRelu" and others):
            raise _err(path, f"{where}: every input but the data tensor must be a constant", fld)
        n = chain.dim()
        if op in _ACT_OPS:
            if op == "Identity":
                pass
            elif op == "PRelu":  # one shared slope (leaky relu) or one per unit
                chain.activate(_prelu(consts[others[0]] if others else None, n, where, path, fld))
            elif op == "Sigmoid" and _is_silu(node, consumers, data):
                mul = next(c for c in consumers[node.output[0]])
                skip.add(list(g.node).index(mul))
                chain.activate(Silu())
                data = mul.output[0]
                continue
            else:
                chain.activate(_activation(node, attrs, path, fld))
            data = node.output[0]
            continue
        gelu = _match_gelu(node, consumers, consts, data) if op in ("Div", "Mul") else None
        if gelu is not None:  # x * 0.5 * (1 + Erf(x / sqrt 2)): torch's Gelu below opset 20
            chain.activate(Gelu())
            skip.update(list(g.node).index(m) for m in gelu[1:])
            data = gelu[-1].output[0]
            continue
        c = consts[others[0]] if others else None
        first = ins[0] == data
        if op == "Gemm":
            if not first or attrs.get("transA", 0):
                raise _err(path, f"{where}: the data must be input A with transA = 0", fld)
            B = consts[ins[1]]
            if B.ndim != 2:
                raise _err(path, f"{where}: B ({ins[1]!r}) must be a matrix, got {B.shape}", fld)
            Bm = B.T if attrs.get("transB", 0) else B  # (in, out)
            if Bm.shape[0] != n:
                raise _err(
                    path, f"{where}: B ({ins[1]!r}) expects {Bm.shape[0]} inputs, gets {n}", fld
                )
            out = Bm.shape[1]
            bias = np.zeros(out)
            if len(ins) > 2:
                bias = float(attrs.get("beta", 1.0)) * _vector(
                    consts[ins[2]], out, f"{where} C ({ins[2]!r})", path, fld
                )
            chain.affine(float(attrs.get("alpha", 1.0)) * Bm.T, bias)
        elif op == "MatMul":
            assert c is not None
            if not first or c.ndim != 2 or c.shape[0] != n:
                raise _err(
                    path,
                    f"{where}: only data @ constant matrix with {n} rows is supported, got "
                    f"shape {c.shape}",
                    fld,
                )
            chain.affine(c.T, np.zeros(c.shape[1]))
        else:
            assert c is not None
            v = _vector(c, n, where, path, fld)
            if op == "Add":
                chain.affine(np.eye(n), v)
            elif op == "Sub":
                if first:
                    chain.affine(np.eye(n), -v)
                else:
                    chain.affine(-np.eye(n), v)
            elif op == "Mul":
                chain.affine(np.diag(v), np.zeros(n))
            else:  # Div
                if not first or np.any(v == 0.0):
                    raise _err(path, f"{where}: only data / nonzero constant is supported", fld)
                chain.affine(np.diag(1.0 / v), np.zeros(n))
        data = node.output[0]
    if data != g.output[0].name:
        raise _err(
            path, f"the chain ends at {data!r}, not at the graph output {g.output[0].name!r}", fld
        )
    layers = chain.finish()
    try:
        return MLP(
            tuple(w for w, _, _ in layers),
            tuple(b for _, b, _ in layers),
            activations=tuple(a for _, _, a in layers),
        )
    except SpecError as exc:
        raise _err(path, str(exc), fld) from None


def _constant(attrs: dict[str, Any], where: str, path: Path, fld: str | None) -> np.ndarray:
    """The float value of a ``Constant`` node (``value``, ``value_float`` or ``value_floats``)."""
    if "value" in attrs:
        arr = numpy_helper.to_array(attrs["value"])
    elif "value_float" in attrs or "value_floats" in attrs:
        arr = np.asarray(attrs.get("value_float", attrs.get("value_floats")))
    else:
        raise _err(
            path,
            f"{where}: only float constants ('value', 'value_float', 'value_floats') are supported",
            fld,
        )
    if not np.issubdtype(arr.dtype, np.floating):
        raise _err(path, f"{where}: constant of dtype {arr.dtype}; only floats", fld)
    return arr.astype(np.float64)


def _prelu(slope, n: int, where: str, path: Path, fld: str | None) -> Activation:
    """The activation of a ``PRelu`` node on ``n`` units: :class:`LeakyRelu` when the slope
    tensor holds one value, :class:`PRelu` when it holds one per unit (shape ``(n,)`` or
    ``(1, n)``, as ``nn.PReLU(num_parameters=n)`` exports it)."""
    if slope is None:
        raise _err(path, f"{where}: the slope input is missing", fld)
    flat = np.asarray(slope, dtype=np.float64).reshape(-1)
    if flat.size and np.all(flat == flat[0]):
        return LeakyRelu(float(flat[0]))
    if slope.shape not in ((n,), (1, n)):
        raise _err(
            path,
            f"{where}: slope tensor of shape {slope.shape}; one slope shared by all units or one "
            f"per unit (shape ({n},)) is supported",
            fld,
        )
    try:
        return PRelu(tuple(flat))
    except SpecError as exc:
        raise _err(path, f"{where}: {exc}", fld) from None


def _near(c: np.ndarray | None, value: float) -> bool:
    """A scalar constant equal to ``value`` up to float32 rounding (the exporters' constants
    are float32 numbers: ``sqrt 2`` is written as 1.4142135381698608)."""
    if c is None or np.size(c) != 1:
        return False
    v = float(np.asarray(c).reshape(-1)[0])
    return abs(v - value) <= _CONST_ULPS * float(np.finfo(np.float32).eps) * abs(value)


def _match_gelu(node, consumers: dict[str, list], consts: dict[str, np.ndarray], x: str):
    """The nodes of ``x * 0.5 * (1 + Erf(x / sqrt 2))`` starting at ``node`` (the division
    ``x / sqrt 2`` or the product ``x * (1 / sqrt 2)``), as ``torch.onnx.export`` writes
    ``nn.GELU()`` below opset 20: ``(x * (1 + erf)) * 0.5`` or ``x * ((1 + erf) * 0.5)``, in
    either operand order. ``None`` unless every intermediate tensor has exactly one consumer
    and ``x`` exactly two (this node and the product)."""

    def const(n, name):  # the constant operand of a two-input node whose other input is name
        ins = list(n.input)
        if len(ins) != 2 or name not in ins:
            return None
        other = ins[1] if ins[0] == name else ins[0]
        return consts.get(other)

    def only(name):
        c = consumers.get(name, [])
        return c[0] if len(c) == 1 else None

    if len(consumers.get(x, [])) != 2 or (node.op_type == "Div" and node.input[0] != x):
        return None
    scale = const(node, x)
    if not (
        (node.op_type == "Div" and _near(scale, math.sqrt(2.0)))
        or (node.op_type == "Mul" and _near(scale, 1.0 / math.sqrt(2.0)))
    ):
        return None
    erf = only(node.output[0])
    if erf is None or erf.op_type != "Erf":
        return None
    add = only(erf.output[0])
    if add is None or add.op_type != "Add" or not _near(const(add, erf.output[0]), 1.0):
        return None
    m1 = only(add.output[0])
    if m1 is None or m1.op_type != "Mul":
        return None
    m2 = only(m1.output[0])
    if m2 is None or m2.op_type != "Mul":
        return None
    if sorted(m1.input) == sorted([x, add.output[0]]):  # (x * (1 + erf)) * 0.5
        ok = _near(const(m2, m1.output[0]), 0.5)
    else:  # x * ((1 + erf) * 0.5)
        ok = _near(const(m1, add.output[0]), 0.5) and sorted(m2.input) == sorted([x, m1.output[0]])
    return (node, erf, add, m1, m2) if ok else None


def _is_silu(node, consumers: dict[str, list], data: str) -> bool:
    """``Sigmoid(x)`` consumed only by ``Mul(x, Sigmoid(x))``, and ``x`` only by these two."""
    outs = consumers.get(node.output[0], [])
    if len(outs) != 1 or outs[0].op_type != "Mul":
        return False
    mul = outs[0]
    return sorted(mul.input) == sorted([data, node.output[0]]) and len(consumers[data]) == 2


def _tolerance(mlp: MLP, dtype: np.dtype, y: np.ndarray) -> float:
    eps = float(np.finfo(dtype).eps)
    fan = sum(int(w.shape[1]) for w in mlp.weights)
    return REFERENCE_ULPS * eps * fan * max(1.0, float(np.max(np.abs(y))))


def check_against_reference(model, mlp: MLP, path: Path, fld: str | None = None) -> float:
    """The largest difference between ``mlp`` and ``onnx.reference`` on ``N_CHECK`` seeded
    standard-normal inputs; a :class:`SpecError` when above the tolerance of the module
    docstring."""
    inp = [i for i in model.graph.input if i.name not in {t.name for t in model.graph.initializer}]
    elem = inp[0].type.tensor_type.elem_type
    dtype = np.dtype(helper.tensor_dtype_to_np_dtype(elem))
    x = np.random.default_rng(CHECK_SEED).standard_normal((N_CHECK, mlp.in_dim))
    try:
        out = list(ReferenceEvaluator(model).run(None, {inp[0].name: x.astype(dtype)}))
    except Exception as exc:  # the reference implementation rejects the graph
        raise _err(
            path, f"onnx.reference cannot run it ({type(exc).__name__}: {exc})", fld
        ) from exc
    ref = np.asarray(out[0], dtype=np.float64).reshape(N_CHECK, -1)
    # the graph saw its inputs rounded to its dtype: evaluate the MLP on the same points
    ours = mlp.apply_np(x.astype(dtype).astype(np.float64))
    if ref.shape != ours.shape:
        raise _err(
            path, f"onnx.reference gives shape {ref.shape}, the conversion {ours.shape}", fld
        )
    diff = float(np.max(np.abs(ref - ours)))
    # onnx.reference expands Gelu into its function body, whose constants (1/sqrt 2, 1/2) are
    # float32 whatever the graph's dtype: such a graph is only float32-accurate there
    has_gelu = any(n.op_type == "Gelu" for n in model.graph.node)
    tol = _tolerance(mlp, np.dtype(np.float32) if has_gelu else dtype, ours)
    if not diff <= tol:
        raise _err(
            path,
            f"the converted network differs from onnx.reference by {diff:.3e} > {tol:.3e} "
            f"({REFERENCE_ULPS} x eps({dtype}) x total fan-in x output scale) on {N_CHECK} random "
            "inputs: an op was read wrongly; please report the file",
            fld,
        )
    return diff


def _f32(v: float) -> bool:
    """Whether ``v`` is exactly a float32 number (an ONNX float attribute keeps it)."""
    return float(np.float32(v)) == v


def write_onnx(mlp: MLP, path: str | Path, dtype: str = "float64") -> Path:
    """Write ``mlp`` as an ONNX graph (see the module docstring); returns the path.

    ``dtype``: ``"float64"`` (the round trip through :func:`read_onnx` is exact) or
    ``"float32"``.
    """
    if dtype not in ("float64", "float32"):
        raise SpecError(f"dtype must be 'float64' or 'float32', got {dtype!r}", field="dtype")
    np_t = np.float64 if dtype == "float64" else np.float32
    elem = TensorProto.DOUBLE if dtype == "float64" else TensorProto.FLOAT
    nodes, inits = [], []
    cur = "x"
    opset = _OPSET
    for k, (w, b, act) in enumerate(zip(mlp.weights, mlp.biases, mlp.activations)):
        inits.append(numpy_helper.from_array(np.asarray(w, dtype=np_t), f"W{k}"))
        inits.append(numpy_helper.from_array(np.asarray(b, dtype=np_t), f"b{k}"))
        nodes.append(
            helper.make_node("Gemm", [cur, f"W{k}", f"b{k}"], [f"a{k}"], name=f"gemm{k}", transB=1)
        )
        cur = f"a{k}"
        if isinstance(act, Identity):
            continue
        if isinstance(act, Silu):
            nodes.append(helper.make_node("Sigmoid", [cur], [f"s{k}"], name=f"sigmoid{k}"))
            nodes.append(helper.make_node("Mul", [cur, f"s{k}"], [f"h{k}"], name=f"silu{k}"))
        elif isinstance(act, PRelu):  # one slope per unit: a slope tensor of the layer width
            slopes = np.asarray(act.slopes, dtype=np_t)
            inits.append(numpy_helper.from_array(slopes, f"slope{k}"))
            nodes.append(helper.make_node("PRelu", [cur, f"slope{k}"], [f"h{k}"], name=f"prelu{k}"))
        elif isinstance(act, LeakyRelu) and not isinstance(act, Relu) and not _f32(act.alpha):
            # an ONNX float attribute is float32: a float64 slope goes in as a tensor (exact)
            inits.append(numpy_helper.from_array(np.array([act.alpha], dtype=np_t), f"slope{k}"))
            nodes.append(helper.make_node("PRelu", [cur, f"slope{k}"], [f"h{k}"], name=f"prelu{k}"))
        else:
            if isinstance(act, Elu) and not _f32(act.alpha):
                raise SpecError(
                    f"elu alpha {act.alpha!r} is not a float32 number, which an ONNX attribute "
                    "must be; use an alpha exact in float32 (0.5, 1.0, ...)"
                )
            if isinstance(act, Gelu):
                opset = max(opset, _GELU_OPSET)
            nodes.append(
                helper.make_node(
                    act.onnx_op, [cur], [f"h{k}"], name=f"{act.name}{k}", **act.onnx_attributes()
                )
            )
        cur = f"h{k}"
    nodes.append(helper.make_node("Identity", [cur], ["y"], name="output"))
    graph = helper.make_graph(
        nodes,
        "drip_cert_policy",
        [helper.make_tensor_value_info("x", elem, ["N", mlp.in_dim])],
        [helper.make_tensor_value_info("y", elem, ["N", mlp.out_dim])],
        initializer=inits,
    )
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", opset)], producer_name="drip-cert"
    )
    model.ir_version = 8 if opset <= 17 else 9
    onnx.checker.check_model(model)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    onnx.save(model, str(tmp))
    tmp.replace(out)
    return out
