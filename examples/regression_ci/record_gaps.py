"""Record the four processes of the DRIP paper for the worked example, in a plain numpy loop.

The README's worked example "Regression tests against your own gaps" (docs/data_format.md for the
file layout). ``plant.toml``'s certified L1-DRAC controller and learned policy run in *your*
simulator: here a hand-written Euler-Maruyama model of the true plant, standing in for a robot
or another simulator. Usage::

    python record_gaps.py plant.toml gaps.npz [--paths 200] [--seed 0]

Writes ``gaps.npz`` with ``t``, ``expert_nominal``, ``learned_nominal``, ``learned_true``,
``learned_l1_true`` (each ``(paths, times, 1)``), ``l1_design`` and ``fingerprint`` (the
certified policy's and design's, ``controller.fingerprint``: validation refuses data recorded
with another); then run ``drip-cert validate plant.toml --data gaps.npz``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from drip_cert.deploy import l1drac_controller, learned_policy

RECORD_EVERY = 10
"""Record every 10th loop step (about 200 recorded times over the 2 s horizon)."""


# your plant, written in your own code (here: what plant.toml describes)
def expert(x: np.ndarray) -> np.ndarray:
    return -x


def nominal_drift(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return -x + u


def true_drift(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return -x + u + 0.1 * np.sin(x)  # the disturbance the certificate only knows bounds of


NOISE = 0.05


def record(spec: str | Path, paths: int = 200, seed: int = 0) -> dict[str, np.ndarray]:
    """The four processes from one set of initial states, the true ones with one noise."""
    controller = l1drac_controller(spec)  # certifies the spec: the certified T_s, omega, ...
    policy = learned_policy(spec)  # pi_IL: (N, n) -> (N, m)
    rng = np.random.default_rng(seed)
    dt = controller.dt
    n_steps = int(2.0 / dt)  # the spec's horizon
    n_steps -= n_steps % RECORD_EVERY
    x0 = rng.uniform(-0.5, 0.5, size=(paths, 1))  # the spec's [initial] support
    xe, xl, xt, xa = (x0.copy() for _ in range(4))
    controller.reset(xa)
    rows: dict[str, list[np.ndarray]] = {k: [x0.copy()] for k in ("e", "l", "t", "a")}
    for j in range(n_steps):
        dw = np.sqrt(dt) * rng.standard_normal(size=(paths, 1))  # one noise for both true runs
        u_a = controller.step(j * dt, xa)  # pi_IL(x) + U_L1 on [t_j, t_j + dt)
        xe = xe + dt * nominal_drift(xe, expert(xe))
        xl = xl + dt * nominal_drift(xl, policy(xl))
        xt = xt + dt * true_drift(xt, policy(xt)) + NOISE * dw
        xa = xa + dt * true_drift(xa, u_a) + NOISE * dw
        if (j + 1) % RECORD_EVERY == 0:
            for k, x in zip("elta", (xe, xl, xt, xa), strict=True):
                rows[k].append(x.copy())
    p = controller.params
    return {
        "t": np.arange(0, n_steps + 1, RECORD_EVERY) * dt,
        "expert_nominal": np.stack(rows["e"], axis=1),
        "learned_nominal": np.stack(rows["l"], axis=1),
        "learned_true": np.stack(rows["t"], axis=1),
        "learned_l1_true": np.stack(rows["a"], axis=1),
        "l1_design": np.array([p.omega, p.lambda_s, p.Ts]),
        "fingerprint": np.array(str(controller.fingerprint)),  # what these data were recorded with
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec")
    ap.add_argument("out")
    ap.add_argument("--paths", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    np.savez(args.out, **record(args.spec, args.paths, args.seed))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
