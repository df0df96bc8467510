"""Write policy.onnx: a 2-16-16-1 ReLU network for examples/unmatched_2d, as torch.onnx.export
writes an nn.Sequential (Linear, ReLU, Linear, ReLU, Linear): Gemm nodes with transB = 1 and
(out, in) float32 weights, Relu nodes, graph input "input" and output "output".

The network is the residual of a residual policy u = -x1 - 2 x2 + r(x) (spec.toml): it is
FITTED by ridge least squares to cancel the known mean of the matched drift,
r(x) ~ -(0.2 + 0.1 tanh(x1)), on a grid of [-1.5, 1.5]^2 (the "training"). The first layer has
16 hinges relu(+-(x1 - t_k)) at knots t_k spread over [-3, 3], the second passes them on (an
identity), and every weight of the first two layers carries a small seeded perturbation, so r
is a generic piecewise-linear map of both states. Built with onnx.helper only (no torch).

    python examples/relu_unmatched_2d/make_policy.py [OUT]   (default: beside this script)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

SEED = 0
PERTURBATION = 0.01  # scale of the random part of the first two layers' weights
RIDGE = 1e-3  # weight of the ridge penalty (per grid point) in the least-squares fit
KNOTS = np.linspace(-3.0, 3.0, 8)  # hinges along x1
FIT_AXIS = np.linspace(-1.5, 1.5, 31)  # each state's values on the least-squares grid


def residual_target(x: np.ndarray) -> np.ndarray:
    """What the residual is fitted to at points ``(N, 2)``: minus the known mean of the matched
    drift of examples/unmatched_2d (its second entry, 0.2 + 0.1 tanh(x1))."""
    return -(0.2 + 0.1 * np.tanh(x[:, 0]))


def weights(seed: int = SEED) -> list[tuple[np.ndarray, np.ndarray]]:
    """The three (W, b) pairs, W of shape (out, in) as in torch.nn.Linear, as float32."""
    rng = np.random.default_rng(seed)
    w0 = np.zeros((16, 2))
    w0[0::2, 0], w0[1::2, 0] = 1.0, -1.0  # units 2k, 2k+1: relu(x1 - t_k), relu(t_k - x1)
    b0 = np.repeat(-KNOTS, 2) * np.tile([1.0, -1.0], 8)
    w0 = w0 + PERTURBATION * rng.standard_normal(w0.shape)
    b0 = b0 + PERTURBATION * rng.standard_normal(16)
    w1 = np.eye(16) + PERTURBATION * rng.standard_normal((16, 16))
    b1 = PERTURBATION * rng.standard_normal(16)
    w0, b0, w1, b1 = (a.astype(np.float32).astype(np.float64) for a in (w0, b0, w1, b1))
    # the fit: features of the first two (rounded) layers on the grid
    x = np.stack(np.meshgrid(FIT_AXIS, FIT_AXIS), axis=-1).reshape(-1, 2)
    h = np.maximum(np.maximum(x @ w0.T + b0, 0.0) @ w1.T + b1, 0.0)
    feats = np.concatenate([h, np.ones((len(x), 1))], axis=1)
    # ridge (weight decay, as training uses): small output weights, a small Lipschitz constant
    reg = np.sqrt(RIDGE * len(x)) * np.eye(feats.shape[1])
    rhs = np.concatenate([residual_target(x), np.zeros(feats.shape[1])])
    coef, *_ = np.linalg.lstsq(np.concatenate([feats, reg]), rhs, rcond=None)
    w2, b2 = coef[None, :16], coef[16:]
    return [(w.astype(np.float32), b.astype(np.float32)) for w, b in ((w0, b0), (w1, b1), (w2, b2))]


def make(out: Path) -> Path:
    nodes, inits, cur = [], [], "input"
    layers = weights()
    for k, (w, b) in enumerate(layers):
        i = 2 * k  # nn.Sequential indices: Linear at 0, 2, 4; ReLU at 1, 3
        inits += [
            numpy_helper.from_array(w, f"{i}.weight"),
            numpy_helper.from_array(b, f"{i}.bias"),
        ]
        gemm_out = f"/{i}/Gemm_output_0" if k < len(layers) - 1 else "output"
        nodes.append(
            helper.make_node(
                "Gemm",
                [cur, f"{i}.weight", f"{i}.bias"],
                [gemm_out],
                name=f"/{i}/Gemm",
                alpha=1.0,
                beta=1.0,
                transB=1,
            )
        )
        cur = gemm_out
        if k < len(layers) - 1:
            nodes.append(
                helper.make_node("Relu", [cur], [f"/{i + 1}/Relu_output_0"], name=f"/{i + 1}/Relu")
            )
            cur = f"/{i + 1}/Relu_output_0"
    graph = helper.make_graph(
        nodes,
        "main_graph",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, ["batch_size", 2])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, ["batch_size", 1])],
        initializer=inits,
    )
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="pytorch"
    )
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(out))
    return out


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("policy.onnx")
    print(make(target))
