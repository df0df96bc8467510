"""Regenerate h.npz, the fixed 'neural network' h(x) of the DRIP paper's example.

The paper says only that h is "a neural network". We fix a seeded tanh MLP 4-16-4 (weights
LeCun-normal, scale 1, seed 4) so that every run of drip-cert sees the same h. Run from the
repository root: ``python examples/paper_4d/make_h.py``.
"""

from pathlib import Path

import numpy as np

from drip_cert.model.mlp import init_mlp

SEED = 4
mlp = init_mlp([4, 16, 4], np.random.default_rng(SEED), activation="tanh")
# non-zero biases so that h(0) != 0 (a generic network, not an odd function)
mlp = type(mlp)(
    mlp.weights,
    tuple(np.random.default_rng(SEED + 1).normal(scale=0.3, size=b.shape) for b in mlp.biases),
    "tanh",
)
OUT = Path(__file__).resolve().parents[2] / "drip_cert" / "data" / "paper_4d" / "h.npz"
mlp.save(OUT)
print("wrote", OUT, "sizes", mlp.sizes)
