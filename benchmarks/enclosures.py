"""Fast MLP enclosures and the learned-loop branch and bound against the existing routes.

1. Jacobian enclosures of the paper's trained policy (``demo_out/policy_tasil.npz``, a tanh MLP
   4-64-64-4) over random boxes of radius 0.5, 0.1, 0.02 in ``[-1, 1]^4``: mean width of the
   plain interval route (``analysis.mlp.enclose_jacobian``) and of the centred route
   (``analysis.mlp.enclose_jacobian_centred``), their ratio, and the time per box.
2. ``max mu_2`` of the paper's learned closed loop ``J = -0.05 I - 0.25 Dh + 0.25 D pi_IL`` on
   ``[-1, 1]^4``: the sound bound reached in ``--time`` seconds by the existing
   ``interval-bnb`` and by ``mlp-bnb`` (same sampled maximum).
3. ``sup ||D(pi_IL - pi*)||_2`` on ``[-1, 1]^4`` in ``--time`` seconds (``mlp-bnb``).

Usage: ``python benchmarks/enclosures.py [--time 10] [--policy demo_out/policy_tasil.npz]``
(the policy file is made by ``make demo``). The last line printed is
``mu2 bound: interval-bnb X, mlp-bnb Y (ratio of distances to the sampled max Z)``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from drip_cert.analysis.contraction.mlp_loop import sup_difference_jacobian_norm, system_mlps
from drip_cert.analysis.contraction.rate import SamplingOptions, contraction_rate
from drip_cert.analysis.networks.block_enclosure import block_enclose_callback
from drip_cert.analysis.networks.mlp import enclose_jacobian
from drip_cert.analysis.networks.mlp.derivatives import enclose_jacobian_centred
from drip_cert.learn.imitation import learned_system
from drip_cert.model.mlp import load_mlp
from drip_cert.spec.load import load_spec

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--time", type=float, default=10.0, help="seconds per branch and bound")
    ap.add_argument("--policy", default=str(ROOT / "demo_out" / "policy_tasil.npz"))
    args = ap.parse_args()
    spec = load_spec(ROOT / "drip_cert" / "data" / "paper_4d" / "paper_4d.toml")
    mlp = load_mlp(args.policy)
    s = learned_system(spec.system, mlp)
    rng = np.random.default_rng(0)
    print("Jacobian enclosures of the 4-64-64-4 policy (200 random boxes per radius)")
    for rad in (0.5, 0.1, 0.02):
        c = rng.uniform(-1 + rad, 1 - rad, (200, 4))
        lo, hi = c - rad, c + rad
        t0 = time.perf_counter()
        a, b = enclose_jacobian(mlp, lo, hi)
        t_old = time.perf_counter() - t0
        t0 = time.perf_counter()
        p, q = enclose_jacobian_centred(mlp, lo, hi)
        t_new = time.perf_counter() - t0
        w_old, w_new = float(np.mean(b - a)), float(np.mean(q - p))
        print(
            f"  r = {rad:5}: width interval {w_old:.4g}, centred {w_new:.4g} "
            f"(ratio {w_new / w_old:.3f}); {1e6 * t_old / 200:.0f} vs {1e6 * t_new / 200:.0f} "
            "us per box"
        )
    J = s.closed_loop_jacobian("learned")
    box = np.array(s.support, dtype=float)
    samp = SamplingOptions()
    t0 = time.perf_counter()
    old = contraction_rate(
        J,
        s.states,
        box,
        enclose=block_enclose_callback(s.blocks),
        method="interval-bnb",
        max_time_s=args.time,
        sampling=samp,
    )
    t_old = time.perf_counter() - t0
    t0 = time.perf_counter()
    new = contraction_rate(
        J, s.states, box, mlps=system_mlps(s), method="mlp-bnb", max_time_s=args.time
    )
    t_new = time.perf_counter() - t0
    print(
        f"learned loop max mu_2 on [-1,1]^4: interval-bnb {old.max_mu_upper:.4g} "
        f"({old.n_boxes} boxes, {t_old:.1f} s), mlp-bnb {new.max_mu_upper:.4g} "
        f"({new.n_boxes} boxes, {t_new:.1f} s); sampled {new.max_mu_sampled:.4g}"
    )
    q = sup_difference_jacobian_norm(s, box, max_time_s=args.time, tol=1e-2)
    if q is not None:
        print(f"sup ||D(pi_IL - pi*)||_2 on [-1,1]^4 <= {q.value:.4g} ({q.note})")
    ratio = (old.max_mu_upper - old.max_mu_sampled) / (new.max_mu_upper - new.max_mu_sampled)
    print(
        f"mu2 bound: interval-bnb {old.max_mu_upper:.4g}, mlp-bnb {new.max_mu_upper:.4g} "
        f"(ratio of distances to the sampled max {ratio:.2f})"
    )


if __name__ == "__main__":
    main()
