"""The DRIP control stack as objects for the user's own loop: the learned policy and L1-DRAC.

:class:`L1DRACController` is a stateful L1-DRAC controller (L1-DRAC (15a)-(15c), composed with
the learned policy as DRIP does, ``pi_ad = pi_IL + U_L1``) with a plain numpy interface::

    controller.reset(x0)          # x_hat(0) = x0, eta(0) = 0, Lambda_hat = 0 on [0, T_s)
    u = controller.step(t, x)     # the input to apply on [t, t + dt): pi_IL(x) + U_L1(t)

It runs the pure step :func:`drip_cert.control.l1drac.l1_step` that the Monte-Carlo engine
(:mod:`drip_cert.sim.kernel`) runs, in the engine's order of operations and on the engine's grid
``t_j = j dt``: ``g(t_j)``, ``pi_IL(x)``, the known drift ``f(t_j, x) + g(t_j) pi_IL(x)`` seen by
the predictor, then the L1-DRAC step (sample at ``j mod k == 0``, ``u = -eta``, filter, predictor).
A user's simulator or robot loop that measures ``x`` at ``t_j``, applies ``u`` until ``t_{j+1}``
and calls :meth:`L1DRACController.step` once per step therefore runs exactly the controller the
certificate's ``rho_L1`` is about (``tests/test_controller.py`` compares a hand-written numpy loop
with the engine path for path).

:class:`PolicyFunction` is the learned policy ``pi_IL`` as a plain callable ``x -> u``.

Both take one state ``(n,)`` or a batch ``(B, n)`` of independent paths. Build them from a spec
or a certificate with :func:`drip_cert.deploy.l1drac_controller` and
:func:`drip_cert.deploy.learned_policy`; here they take the numeric model and the parameters.

Coordinates. A certificate computed in metric coordinates ``z = Theta x``
(``Certificate.coordinates``) certifies the controller of the system in ``z``: its predictor and
its ``Theta_ad`` live in ``z``. With ``theta`` given, the controller maps every measurement
``z = Theta x`` (and ``x0``) before the step; the input ``u`` needs no map (``g_z = Theta g``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1Params, L1State, l1_init, l1_step
from drip_cert.errors import SpecError
from drip_cert.model.fingerprint import Fingerprint
from drip_cert.model.numeric import SimModel

__all__ = ["L1DRACController", "PolicyFunction"]

TIME_TOL_STEPS = 1e-6
"""How far (in steps ``dt``) the ``t`` a caller passes may be from the controller's grid time
``j dt``: a clock that adds ``dt`` at every step drifts by a few ulps per step (1e-10 steps after
10^6 steps); a missed or repeated step is off by a whole step."""

# Theta_ad and the step counter depend on time only: one copy for the whole batch (as the engine)
_SHARED: L1State[int | None] = L1State(x_hat=0, eta=0, lam_hat=0, theta=None, step=None)


def _as_batch(x: Any, n: int, what: str) -> tuple[np.ndarray, bool]:
    """``x`` as a float64 ``(B, n)`` array and whether it was a single ``(n,)`` state."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == n:
        return a[None, :], True
    if a.ndim == 2 and a.shape[1] == n and a.shape[0] >= 1:
        return a, False
    raise SpecError(
        f"expected a state of shape ({n},) or a batch (B, {n}), got shape {a.shape}", field=what
    )


class PolicyFunction:
    """The learned policy ``pi_IL`` as a plain callable: ``u = policy(x)``.

    Parameters
    ----------
    model
        The numeric model whose ``learned`` policy is wrapped.
    name
        Free text (the spec's system name), for ``repr``.
    fingerprint
        The :class:`~drip_cert.model.fingerprint.Fingerprint` of the policy (``design`` is
        ``None``): recorded data of this policy carry it (``docs/data_format.md``).

    Notes
    -----
    ``policy(x)`` takes ``(n,)`` and returns ``(m,)``, or takes ``(B, n)`` and returns
    ``(B, m)``; float64 numpy in and out. It evaluates the same jax function as the engine and
    the certificate (``System.numeric.learned``), compiled once per batch size.
    """

    def __init__(
        self, model: SimModel, name: str = "", *, fingerprint: Fingerprint | None = None
    ) -> None:
        if not isinstance(model, SimModel):
            raise SpecError("model must be a SimModel (System.numeric)", field="model")
        if model.learned is None:
            raise SpecError(
                "the model has no learned policy: add [policy] learned to the spec (or train "
                "one with `drip-cert train`)",
                field="policy.learned",
            )
        self.n = model.n
        self.m = model.m
        self.name = name or model.name
        self.fingerprint = fingerprint
        self._fn = jax.jit(jax.vmap(model.learned))

    def __call__(self, x: Any) -> np.ndarray:
        """``pi_IL(x)``: ``(n,) -> (m,)`` or ``(B, n) -> (B, m)``."""
        xb, single = _as_batch(x, self.n, "x")
        u = np.asarray(self._fn(jnp.asarray(xb)))
        return u[0] if single else u

    def __repr__(self) -> str:
        return f"PolicyFunction({self.name!r}, n={self.n}, m={self.m})"


class L1DRACController:
    """L1-DRAC (15a)-(15c) composed with the learned policy, as a stateful numpy controller.

    Parameters
    ----------
    model
        The numeric model the controller was designed for (the certificate's system:
        ``Certificate.system.numeric``); its ``f``, ``g``, ``learned`` and ``theta_ad`` enter the
        predictor (15c) and the adaptation law (15b). Its uncertainty is NOT used (unknown to the
        controller).
    params
        :class:`~drip_cert.control.l1drac.L1Params`: ``omega``, ``lambda_s``, ``Ts`` of the
        design and the loop's step ``dt`` (``Ts = k dt``, ``k`` integer).
    theta
        ``None``, or the ``n x n`` matrix ``Theta`` of a certificate in coordinates
        ``z = Theta x``: measurements are mapped to ``z`` before the step.
    verdict
        Free text carried along (the certificate's verdict), for ``repr`` and reports.
    fingerprint
        The certificate's :class:`~drip_cert.model.fingerprint.Fingerprint` (policy and design):
        data recorded with this controller carry it (``docs/data_format.md``).

    Examples
    --------
    A plain numpy loop over the true system (Euler-Maruyama with the controller's ``dt``)::

        from drip_cert.deploy import l1drac_controller, learned_policy
        controller = l1drac_controller("examples/pendulum/pendulum.toml")  # certifies (~10 s)
        dt = controller.dt
        x = np.array([0.3, -0.2])
        controller.reset(x)
        for j in range(round(1.0 / dt)):
            u = controller.step(j * dt, x)          # pi_IL(x) + U_L1, held on [t, t + dt)
            x = x + dt * true_drift(x, u) + np.sqrt(dt) * true_diffusion(x) @ rng.standard_normal(1)

    ``controller.u_policy`` and ``controller.u_l1`` hold the two parts of the last input.
    """

    def __init__(
        self,
        model: SimModel,
        params: L1Params,
        *,
        theta: Any = None,
        verdict: str = "",
        fingerprint: Fingerprint | None = None,
    ) -> None:
        if not isinstance(model, SimModel):
            raise SpecError("model must be a SimModel (System.numeric)", field="model")
        if not isinstance(params, L1Params):
            raise SpecError("params must be an L1Params", field="params")
        if model.learned is None:
            raise SpecError(
                "L1-DRAC in DRIP wraps the learned policy, and the model has none: add "
                "[policy] learned to the spec",
                field="policy.learned",
            )
        if model.g_state:
            raise SpecError(
                "the input operator g depends on the state; L1-DRAC needs g(t) (its adaptation "
                "law and filter assume a state-independent input matrix): deploy the learned "
                "policy alone, or rewrite the inputs so that g depends on t only "
                "(docs/recipes.md)",
                field="dynamics.g",
            )
        self.model = model
        self.params = params
        self.n, self.m = model.n, model.m
        self.verdict = verdict
        self.fingerprint = fingerprint
        self._theta: np.ndarray | None = None
        if theta is not None:
            th = np.asarray(theta, dtype=np.float64)
            if th.shape != (self.n, self.n) or not np.all(np.isfinite(th)):
                raise SpecError(
                    f"must be a finite {self.n} x {self.n} matrix, got shape {th.shape}",
                    field="theta",
                )
            self._theta = th
        self._state: L1State[Any] | None = None
        self._batch: int = 0
        self._single = True
        self.u_policy: np.ndarray | None = None
        self.u_l1: np.ndarray | None = None
        self._init = jax.jit(jax.vmap(l1_init, in_axes=(0, None), out_axes=_SHARED))
        self._step = jax.jit(_make_step(model, params))

    # ------------------------------------------------------------------------------ public
    @property
    def dt(self) -> float:
        """The loop's step: :meth:`step` is called at ``t_j = j dt``."""
        return self.params.dt

    @property
    def design(self) -> dict[str, float]:
        """``omega``, ``lambda_s``, ``Ts`` and ``dt`` (save ``[omega, lambda_s, Ts]`` as the
        ``l1_design`` array of recorded data, ``docs/data_format.md``)."""
        p = self.params
        return {"omega": p.omega, "lambda_s": p.lambda_s, "Ts": p.Ts, "dt": p.dt}

    @property
    def theta(self) -> np.ndarray | None:
        """``Theta`` of a controller in coordinates ``z = Theta x`` (a copy), else ``None``."""
        return None if self._theta is None else self._theta.copy()

    @property
    def steps(self) -> int:
        """Steps taken since :meth:`reset` (the next :meth:`step` is at ``t = steps * dt``)."""
        if self._state is None:
            return 0
        return int(self._state.step)

    def reset(self, x0: Any) -> None:
        """Start at ``t = 0`` from ``x0`` (``(n,)``, or ``(B, n)`` for a batch of paths).

        Implements the initial conditions of L1-DRAC (15): ``x_hat(0) = x0``, ``eta(0) = 0``
        (so ``U_L1 = 0`` on the first step) and ``Lambda_hat = 0`` on ``[0, T_s)``.
        """
        xb, single = _as_batch(x0, self.n, "x0")
        if not np.all(np.isfinite(xb)):
            raise SpecError(f"the initial state is not finite: {xb.tolist()}", field="x0")
        theta0 = self.model.theta_ad(jnp.float64(0.0))
        self._state = self._init(jnp.asarray(self._to_z(xb)), theta0)
        self._batch = xb.shape[0]
        self._single = single
        self.u_policy = self.u_l1 = None

    def step(self, t: float, x: Any) -> np.ndarray:
        """The input on ``[t, t + dt)`` for the state ``x`` measured at ``t``.

        Parameters
        ----------
        t
            The time of the measurement; must be the controller's grid time ``j dt`` (``j`` =
            steps since :meth:`reset`) within :data:`TIME_TOL_STEPS` steps. The controller uses
            ``j dt`` itself (as the engine does), so a drifting clock changes nothing.
        x
            The measured state, the shape given to :meth:`reset`.

        Returns
        -------
        numpy.ndarray
            ``pi_IL(x) + U_L1(t)`` (DRIP's ``pi_ad``), ``(m,)`` or ``(B, m)``; its parts are in
            :attr:`u_policy` and :attr:`u_l1`.
        """
        if self._state is None:
            raise SpecError("call reset(x0) before step(t, x)", field="L1DRACController")
        j = int(self._state.step)
        t_grid = j * self.params.dt
        if not (math.isfinite(float(t)) and abs(float(t) - t_grid) <= TIME_TOL_STEPS * self.dt):
            raise SpecError(
                f"step {j} is at t = {t_grid!r} (j dt, dt = {self.dt!r}), got t = {t!r}: call "
                "step once per dt, in order, starting at t = 0 after reset",
                field="t",
            )
        xb, single = _as_batch(x, self.n, "x")
        if xb.shape[0] != self._batch or single != self._single:
            raise SpecError(
                f"reset was given {'one state' if self._single else f'{self._batch} paths'}, "
                f"step got shape {np.shape(x)}",
                field="x",
            )
        if not np.all(np.isfinite(xb)):
            raise SpecError(
                f"the measured state at t = {t_grid:g} is not finite (the loop diverged?)",
                field="x",
            )
        u, pi, ul1, self._state = self._step(self._state, jnp.asarray(self._to_z(xb)))
        self.u_policy = self._out(pi)
        self.u_l1 = self._out(ul1)
        return self._out(u)

    def __repr__(self) -> str:
        p = self.params
        return (
            f"L1DRACController(omega={p.omega:g}, lambda_s={p.lambda_s:g}, Ts={p.Ts:g}, "
            f"dt={p.dt:g}, n={self.n}, m={self.m}"
            + (", in coordinates z = Theta x" if self._theta is not None else "")
            + (f", verdict={self.verdict!r}" if self.verdict else "")
            + ")"
        )

    # ----------------------------------------------------------------------------- private
    def _to_z(self, xb: np.ndarray) -> np.ndarray:
        if self._theta is None:
            return xb
        return xb @ self._theta.T

    def _out(self, a: Any) -> np.ndarray:
        arr = np.asarray(a)
        return arr[0] if self._single else arr


def _make_step(model: SimModel, params: L1Params) -> Callable:
    """``(state, x (B, n)) -> (u, pi_IL(x), U_L1, state)``: the engine's ``learned_l1_true``
    step of :mod:`drip_cert.sim.kernel` without the plant (same operations, same order)."""
    dt = params.dt
    f_b = jax.vmap(model.f, in_axes=(None, 0))
    learned = model.learned
    assert learned is not None  # checked by the constructor
    learned_b = jax.vmap(learned)
    l1_b = jax.vmap(
        lambda st, x, fk, g_t, th: l1_step(params, st, x, fk, g_t, th),
        in_axes=(_SHARED, 0, 0, None, None),
        out_axes=(0, _SHARED),
    )

    def step(state, x):
        # the engine's time: t_j = j dt with j the uint32 step counter
        t = state.step.astype(jnp.uint32).astype(jnp.float64) * dt
        g_t = model.g(t, jnp.zeros(model.n))  # g(t): the constructor refuses g(t, x)
        pi = learned_b(x)
        fk = f_b(t, x) + pi @ g_t.T  # f(t, x) + g(t) pi_IL(x), as the engine's known_drift
        u_l1, state = l1_b(state, x, fk, g_t, model.theta_ad(t))
        return pi + u_l1, pi, u_l1, state

    return step
