"""TaSIL vs BC vs DAgger vs DART in the residual class on one spec: the policy's value and
Jacobian errors against the expert on the training and held-out expert states, K, best loss,
the network's product of layer spectral norms (docs/baselines.md, "Why TaSIL does not win").

Usage (repository root): ``python docs/baselines/residual/policy_errors.py SPEC`` (100
trajectories, 500 steps, seed 0: the settings of the residual table).
"""

import dataclasses
import json
import sys

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.learn.imitation import demonstration_set, train_on_system
from drip_cert.spec import load_spec
from drip_cert.spec.settings import TRAIN_METHODS

spec = load_spec(sys.argv[1])
st = dataclasses.replace(spec.settings.tasil, trajectories=100, steps=500, seed=0)
s = spec.system
demos = demonstration_set(s, st)
pe = s.numeric.expert
out = {}
for m in TRAIN_METHODS:
    tp = train_on_system(s, st, method=m, demonstrations=demos, structure=spec.structure)
    pl = tp.system.numeric.learned
    row = {
        "K": None if tp.result.linear is None else np.asarray(tp.result.linear).tolist(),
        "best_val_loss": tp.result.best_val_loss,
        "mlp_lip_product": float(np.prod([np.linalg.norm(W, 2) for W in tp.mlp.weights])),
    }
    for name, d in (("train", demos.train), ("heldout", demos.heldout)):
        X = jnp.asarray(d.states.reshape(-1, s.n))
        e0 = jax.vmap(lambda x, pl=pl: pl(x) - pe(x))(X)
        e1 = jax.vmap(jax.jacfwd(lambda x, pl=pl: pl(x) - pe(x)))(X)
        row[f"{name}_max_value_err"] = float(jnp.max(jnp.abs(e0)))
        row[f"{name}_max_jac_err"] = float(
            jnp.max(jnp.linalg.norm(e1.reshape(e1.shape[0], s.m, s.n), axis=(1, 2), ord=2))
        )
    out[m] = row
    print(m, json.dumps(row), flush=True)
