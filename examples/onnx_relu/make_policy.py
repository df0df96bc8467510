"""Write policy.onnx: a 2-16-16-1 ReLU policy as torch.onnx.export writes an nn.Sequential
(Linear, ReLU, Linear, ReLU, Linear): Gemm nodes with transB = 1 and (out, in) float32 weights,
Relu nodes, graph input "input" and output "output" with a dynamic batch dimension.

The network is u = -x2 written with ReLUs (relu(z) - relu(-z) = z, spread over 16 units) plus a
small seeded perturbation, as a trained network would be: nonlinear, piecewise linear, close to
the expert u = -x2 of spec.toml. Built with onnx.helper only (torch is not needed).

    python examples/onnx_relu/make_policy.py [OUT]   (default: policy.onnx beside this script)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

SEED = 0
PERTURBATION = 0.02  # scale of the random part of every weight


def weights(seed: int = SEED) -> list[tuple[np.ndarray, np.ndarray]]:
    """The three (W, b) pairs, W of shape (out, in) as in torch.nn.Linear."""
    rng = np.random.default_rng(seed)
    w0 = np.zeros((16, 2))
    w0[0::2, 1], w0[1::2, 1] = 1.0, -1.0  # units 2k, 2k+1: relu(x2), relu(-x2)
    w1 = np.eye(16)
    w2 = np.zeros((1, 16))
    w2[0, 0::2], w2[0, 1::2] = -1.0 / 8, 1.0 / 8  # sum: -(relu(x2) - relu(-x2)) = -x2
    layers = []
    for w in (w0, w1, w2):
        w = w + PERTURBATION * rng.standard_normal(w.shape)
        b = PERTURBATION * rng.standard_normal(w.shape[0])
        layers.append((w.astype(np.float32), b.astype(np.float32)))
    return layers


def make(out: Path) -> Path:
    nodes, inits, cur = [], [], "input"
    layers = weights()
    for k, (w, b) in enumerate(layers):
        i = 2 * k  # nn.Sequential indices: Linear at 0, 2, 4; ReLU at 1, 3
        inits += [
            numpy_helper.from_array(w, f"{i}.weight"),
            numpy_helper.from_array(b, f"{i}.bias"),
        ]
        gemm_out = f"/{i}/Gemm_output_0"
        nodes.append(
            helper.make_node(
                "Gemm",
                [cur, f"{i}.weight", f"{i}.bias"],
                [gemm_out if k < len(layers) - 1 else "output"],
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
