"""Random contracting systems for the delta-ISS checks (DRIP Prop. 1 and its corollary).

Each system is ``x' = A x + c tanh(W x) + g v(t)`` with ``A = S - P P^T - alpha I`` (``S``
skew), ``alpha = lambda + |c| ||W||_2``, so that the Jacobian
``A + c diag(sech^2(W x)) W`` has Euclidean log norm ``mu_2 <= -lambda`` by construction
(``mu_2(A) <= -alpha`` and ``||c diag(.) W||_2 <= |c| ||W||_2``). A fraction of the instances
are linear (``c = 0``, ``P = 0``): then ``mu_2 = -lambda`` exactly and a constant input along
the top singular direction of ``g`` makes the comparison bound tight, which is what makes the
numerical checks able to fail.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ContractingSystem:
    """``x' = A x + c tanh(W x) + g v`` with log-norm rate ``lam`` (see module docstring)."""

    A: np.ndarray
    W: np.ndarray
    c: float
    g: np.ndarray
    lam: float

    def drift(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Right-hand side at state ``x`` and input perturbation ``v``."""
        return self.A @ x + self.c * np.tanh(self.W @ x) + self.g @ v

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Jacobian of the drift in ``x``."""
        s = 1.0 / np.cosh(self.W @ x) ** 2
        return self.A + self.c * (s[:, None] * self.W)


def random_contracting_system(rng: np.random.Generator, *, linear: bool) -> ContractingSystem:
    """Draw a system with ``mu_2(Jacobian) <= -lam`` everywhere (exactly ``-lam`` if linear)."""
    n = int(rng.integers(2, 6))
    m = int(rng.integers(1, n + 1))
    lam = float(rng.uniform(0.2, 2.0))
    K = rng.normal(size=(n, n))
    S = (K - K.T) * rng.uniform(0.0, 2.0)
    if linear:
        S = S * float(rng.integers(0, 2))  # half of the linear systems are normal: bound is tight
        W = np.zeros((n, n))
        c = 0.0
        P = np.zeros((n, n))
    else:
        W = rng.normal(size=(n, n))
        c = float(rng.uniform(-1.0, 1.0))
        P = rng.normal(size=(n, n)) * rng.uniform(0.0, 0.7)
    alpha = lam + abs(c) * np.linalg.norm(W, 2)
    A = S - P @ P.T - alpha * np.eye(n)
    g = rng.normal(size=(n, m)) * rng.uniform(0.2, 2.0)
    return ContractingSystem(A=A, W=W, c=c, g=g, lam=lam)


def log_norm_2(M: np.ndarray) -> float:
    """Euclidean log norm ``mu_2(M) = lambda_max((M + M^T)/2)``."""
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1])
