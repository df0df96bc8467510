"""Linear models and gain experts in a spec, written the way control users write them.

* ``[dynamics]`` ``A = [[...]]``, ``B = [[...]]`` (numbers) instead of the expressions ``f``,
  ``g``: the known drift is ``f(x) = A x`` and the input operator ``g = B``;
* ``[policy]`` ``expert = { K = [[...]] }``: the expert ``u = -K x`` (the sign convention of
  ``scipy``/MATLAB ``lqr``);
* ``[policy]`` ``expert = "lqr"`` with ``[policy.lqr] Q = [[...]], R = [[...]]``: ``K = R^-1 B^T P``
  with ``P`` the stabilising solution of the continuous algebraic Riccati equation
  (:func:`scipy.linalg.solve_continuous_are`), designed on ``(A, B)`` or, when the dynamics are
  expressions, on their linearisation at ``x = 0`` (``A = df/dx(0)``, ``B = g``).

Every number is read exactly: a TOML decimal becomes the rational of its decimal text, digit for
digit (``0.1`` is ``1/10``, ``0.6546960439030461848070769`` keeps its 25 digits, as in
expressions; :mod:`drip_cert.model.literals`). The LQR gain is a float matrix from the Riccati
solver; its entries are taken as the exact rationals of those floats, so the expert in the
:class:`System` is exactly the policy that is certified, and :class:`ExpertGain` records where
``K`` came from (``Q``, ``R``, the closed-loop eigenvalues). Every bad value is a
:class:`~drip_cert.errors.SpecError` naming the file, ``table.key``, the value and the fix.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.errors import SpecError
from drip_cert.model.blocks import block_applications
from drip_cert.model.literals import exact_number
from drip_cert.spec.settings import Field, TableReader, toml_text

Rows = tuple[tuple[sp.Rational, ...], ...]
"""A matrix of exact rationals, row by row, as read from the spec."""

PSD_RTOL = 1e-12
"""Q may be singular: its smallest eigenvalue (LAPACK ``eigvalsh``, accurate to a few ulps of
``||Q||``) must be >= -PSD_RTOL ||Q||."""

PD_RTOL = 1e-12
"""R must be invertible in floating point: its smallest eigenvalue must exceed PD_RTOL ||R||
(beyond LAPACK's few-ulp error, so ``R^-1`` is meaningful)."""

RANK_RTOL = 1e-9
"""PBH rank test of stabilisability and detectability: a singular value of ``[A - s I, B]`` below
RANK_RTOL times the largest one counts as zero (float eigenvalues of A carry errors of about
eps ||A|| cond, far above eps)."""

AXIS_RTOL = 1e-9
"""A mode of A counts as unstable (or on the imaginary axis) when its real part is >= -AXIS_RTOL
max(1, ||A||): the float eigenvalue cannot tell it from marginal."""

HURWITZ_RTOL = 1e-9
"""The closed loop ``A - B K`` is accepted as Hurwitz only when every eigenvalue has real part
< -HURWITZ_RTOL max(1, ||A - B K||): a float eigenvalue closer to the axis than that is not
distinguishable from marginal stability."""

_ENTRY_RULE = "a finite number (a TOML integer or float)"
_LQR_KEYS = {
    "Q": "state weight of the LQR cost int x'Qx + u'Ru dt, n x n, symmetric positive semidefinite",
    "R": "input weight of the LQR cost, m x m, symmetric positive definite",
}
_K_KEYS = {"K": "gain of the expert u = -K x (scipy/MATLAB lqr sign), m x n"}


# ------------------------------------------------------------------------------ reading numbers
def _example(rows: int, cols: int, identity: bool = False) -> str:
    """A TOML matrix literal of the right shape (identity or zeros), for fixes."""
    mat = [[(1 if identity and i == j else 0) for j in range(cols)] for i in range(rows)]
    return toml_text(mat)


def read_number_matrix(
    value: Any,
    fld: Field,
    rows: int | None,
    cols: int | None,
    shape: str,
    *,
    identity_example: bool = False,
) -> Rows:
    """A matrix of finite TOML numbers, as exact rationals.

    Parameters
    ----------
    value
        As parsed from TOML: a list of rows, each a list of numbers.
    fld
        Where it is (``dynamics.A``), for messages.
    rows, cols
        The required shape (``None``: any, at least 1).
    shape
        The shape in words for messages, e.g. ``"2 x 2 (n x n: one row and one column per
        state)"``.
    identity_example
        The fix shows an identity of the right shape (else zeros).
    """
    r_ex = rows if rows is not None else 1
    c_ex = cols if cols is not None else 1
    example = f"write {fld.key} = {_example(r_ex, c_ex, identity_example)}"
    rule = f"a {shape} matrix of numbers, written as a list of rows"
    if not isinstance(value, list) or not value:
        raise fld.error(value, rule, example)
    if rows is not None and len(value) != rows:
        raise fld.error(value, rule, f"it has {len(value)} rows, not {rows}; {example}")
    width = None
    for i, row in enumerate(value):
        if not isinstance(row, list) or not row:
            raise fld.error(value, rule, f"row {i} is not a non-empty list of numbers; {example}")
        if width is None:
            width = len(row)
        elif len(row) != width:
            raise fld.error(
                value, rule, f"row {i} has {len(row)} entries but row 0 has {width}; {example}"
            )
    if cols is not None and width != cols:
        raise fld.error(value, rule, f"its rows have {width} entries, not {cols}; {example}")
    out = []
    for i, row in enumerate(value):
        out_row = []
        for j, v in enumerate(row):
            if (
                isinstance(v, bool)
                or not isinstance(v, int | float)
                or (isinstance(v, float) and not math.isfinite(v))
            ):
                entry = Field(fld.table, f"{fld.key}[{i}][{j}]", fld.path, fld.meaning)
                raise entry.error(
                    v,
                    _ENTRY_RULE,
                    "write a number such as 0.5 (a matrix holds numbers; write a nonlinear or "
                    "symbolic model with the expressions f, g or an expert list instead)",
                )
            try:
                out_row.append(exact_number(v))  # a TOML float: the rational of its text
            except ValueError as exc:  # an exponent beyond MAX_LITERAL_EXPONENT
                key = f"{fld.key}[{i}][{j}]"
                raise SpecError(str(exc), field=f"{fld.table}.{key}", path=fld.path) from None
        out.append(tuple(out_row))
    return tuple(out)


def _float(mat: Rows | sp.MatrixBase) -> np.ndarray:
    return np.array([[float(e) for e in row] for row in _rows(mat)], dtype=float)


def _rows(mat: Rows | sp.MatrixBase) -> list[list[Any]]:
    if isinstance(mat, sp.MatrixBase):
        return mat.tolist()
    return [list(r) for r in mat]


# --------------------------------------------------------------------------- the linear model
def linear_dynamics(
    dyn: Mapping[str, Any], n: int, states: Sequence[sp.Symbol], path: str | None
) -> tuple[list[sp.Expr], list[list[sp.Rational]], np.ndarray, np.ndarray]:
    """``[dynamics] A, B`` read into ``f = A x`` and ``g = B`` (exact rationals), with ``A``
    and ``B`` as floats for a gain design: ``(f, g, A, B)``."""
    fa = Field("dynamics", "A", path, "state matrix of the linear model dx/dt = A x + B u")
    fb = Field("dynamics", "B", path, "input matrix of the linear model dx/dt = A x + B u")
    A = read_number_matrix(
        dyn["A"], fa, n, n, f"{n} x {n} (n x n: one row and one column per state)"
    )
    B = read_number_matrix(
        dyn["B"], fb, n, None, f"{n} x m (one row per state, one column per input)"
    )
    x = sp.Matrix(states)
    f = list(sp.Matrix(A) * x)
    g = [list(row) for row in B]
    return f, g, _float(A), _float(B)


def linearise(
    f: Sequence[sp.Expr],
    g: Sequence[Sequence[sp.Expr]],
    states: Sequence[sp.Symbol],
    t: sp.Symbol,
    path: str | None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(A, B) = (df/dx(0), g(0))`` as floats, for an LQR design on a nonlinear model (a
    state-dependent ``g`` is read at ``x = 0``: at ``(x, u) = (0, 0)`` the input term's state
    derivative ``d/dx [g(x) u]`` vanishes).

    The design needs a time-invariant linearisation at an equilibrium: ``f(0) = 0``, ``df/dx(0)``
    and ``g`` free of ``t``, and no blocks in ``f`` (their derivatives are not evaluated here).
    """
    fm = sp.Matrix(f)
    gm = sp.Matrix(g)
    fix = (
        "design the gain yourself and write it as expert = { K = [[...]] }, or write the model "
        "as [dynamics] A, B"
    )
    blocks = sorted({type(a).__name__ for e in fm for a in block_applications(e)})
    if blocks:
        raise SpecError(
            f'expert = "lqr" needs the linearisation of f at x = 0, but f uses the block(s) '
            f"{blocks}, which are not linearised for an LQR design; {fix}",
            field="policy.expert",
            path=path,
        )
    at0 = {s: 0 for s in states}
    f0 = fm.subs(at0)
    J = fm.jacobian(list(states)).subs(at0)
    gm = gm.subs(at0)
    if t in set().union(*(e.free_symbols for e in [*f0, *J, *gm])):
        raise SpecError(
            f'expert = "lqr" needs a time-invariant linearisation at x = 0, but f(0), df/dx(0) '
            f"or g depends on {t}; {fix}",
            field="policy.expert",
            path=path,
        )
    try:
        f0v = np.array([complex(sp.N(e)) for e in f0])
        A = np.array([[complex(sp.N(e)) for e in row] for row in J.tolist()])
        B = np.array([[complex(sp.N(e)) for e in row] for row in gm.tolist()])
    except (TypeError, ValueError) as exc:
        raise SpecError(
            f'expert = "lqr": cannot evaluate the linearisation of f at x = 0 ({exc}); {fix}',
            field="policy.expert",
            path=path,
        ) from None
    if (
        np.any(np.abs(f0v.imag) > 0)
        or np.any(np.abs(A.imag) > 0)
        or not (np.all(np.isfinite(A.real)) and np.all(np.isfinite(B.real)))
    ):
        raise SpecError(
            f'expert = "lqr": the linearisation of f at x = 0 is not a finite real matrix '
            f"(df/dx(0) = {J.tolist()}); {fix}",
            field="policy.expert",
            path=path,
        )
    if np.any(f0v.real != 0):
        raise SpecError(
            f'expert = "lqr" designs the gain on the linearisation at x = 0, which must be an '
            f"equilibrium of the known drift, but f(0) = {[str(e) for e in f0]}; shift the "
            f"states so that f(0) = 0, or {fix}",
            field="policy.expert",
            path=path,
        )
    return A.real.copy(), B.real.copy()


# ------------------------------------------------------------------------------ gain experts
@dataclass(frozen=True, eq=False)
class ExpertGain:
    """Where a linear expert ``u = -K x`` came from.

    Attributes
    ----------
    K
        The gain, m x n exact rationals (the expert of the System is exactly ``-K x``).
    source
        ``"K"`` (written in the spec) or ``"lqr"`` (solved from ``Q``, ``R``).
    Q, R
        The LQR weights as written (``source == "lqr"``), else ``None``.
    linearised
        The design model ``(A, B)`` is the linearisation of ``f, g`` at ``x = 0`` (not the
        model itself).
    closed_loop_eigenvalues
        Eigenvalues of ``A - B K`` of the design model (float, LAPACK), sorted by real part; empty
        when no linear model exists (a given ``K`` on a model that cannot be linearised).
    """

    K: sp.ImmutableMatrix
    source: str
    Q: tuple[tuple[float, ...], ...] | None = None
    R: tuple[tuple[float, ...], ...] | None = None
    linearised: bool = False
    closed_loop_eigenvalues: tuple[complex, ...] = ()

    @property
    def K_float(self) -> np.ndarray:
        """``K`` as a float array (for the LQR gain: exactly the solver's floats)."""
        return _float(self.K)

    @property
    def note(self) -> str:
        """One line for reports: the expert, where ``K`` came from, the closed-loop poles."""
        k = toml_text(self.K_float.tolist())
        if self.source == "lqr":
            model = (
                "the linearisation at x = 0 (A = df/dx(0), B = g)"
                if self.linearised
                else ("the model (A, B)")
            )
            head = (
                f"expert u = -K x, K = {k} from LQR (scipy.linalg.solve_continuous_are) on "
                f"{model} with Q = {toml_text(self.Q)}, R = {toml_text(self.R)}; the entries of K "
                "are the solver's floats taken as exact rationals"
            )
        else:
            head = f"expert u = -K x with the given K = {k}"
        if self.closed_loop_eigenvalues:
            eigs = ", ".join(_complex_text(z) for z in self.closed_loop_eigenvalues)
            where = "of the linearisation " if self.linearised else ""
            head += f"; closed-loop eigenvalues {where}of A - B K: {eigs}"
        return head

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: K (floats; exact rationals as strings), source, Q, R, eigenvalues."""
        return {
            "source": self.source,
            "K": self.K_float.tolist(),
            "K_exact": [[str(e) for e in row] for row in self.K.tolist()],
            "Q": None if self.Q is None else [list(r) for r in self.Q],
            "R": None if self.R is None else [list(r) for r in self.R],
            "linearised": self.linearised,
            "closed_loop_eigenvalues": [[z.real, z.imag] for z in self.closed_loop_eigenvalues],
            "note": self.note,
        }


def _complex_text(z: complex) -> str:
    if z.imag == 0:
        return f"{z.real:.6g}"
    sign = "+" if z.imag > 0 else "-"
    return f"{z.real:.6g} {sign} {abs(z.imag):.6g}i"


def _eigenvalues(acl: np.ndarray) -> tuple[complex, ...]:
    eig = np.linalg.eigvals(acl)
    order = np.lexsort((eig.imag, eig.real))
    return tuple(complex(z) for z in eig[order])


def gain_expert(
    value: Mapping[str, Any],
    m: int,
    states: Sequence[sp.Symbol],
    design: tuple[np.ndarray, np.ndarray, bool] | None,
    path: str | None,
) -> tuple[list[sp.Expr], ExpertGain]:
    """``expert = { K = [[...]] }``: the expert ``-K x`` (exact) and its record. ``design`` is the
    linear(ised) model ``(A, B, linearised)`` when there is one (for the closed-loop poles)."""
    n = len(states)
    reader = TableReader("policy.expert", value, _K_KEYS, path)
    if "K" not in value:
        raise SpecError(
            f"expert = {toml_text(value)} has no gain: write expert = {{ K = "
            f"{_example(m, n)} }} (u = -K x, m x n = {m} x {n})",
            field="policy.expert.K",
            path=path,
        )
    K = read_number_matrix(
        value["K"],
        reader.field_of("K"),
        m,
        n,
        f"{m} x {n} (m x n: one row per input, one column per state)",
    )
    Km = sp.ImmutableMatrix(K)
    expert = list(-Km * sp.Matrix(states))
    eigs: tuple[complex, ...] = ()
    linearised = False
    if design is not None:
        A, B, linearised = design
        eigs = _eigenvalues(A - B @ _float(K))
    return expert, ExpertGain(K=Km, source="K", linearised=linearised, closed_loop_eigenvalues=eigs)


def _symmetric(mat: Rows, fld: Field, value: Any) -> None:
    """Symmetric exactly as written: a user writes both triangles, and an asymmetric entry is a
    typo, not rounding."""
    n = len(mat)
    for i in range(n):
        for j in range(i + 1, n):
            if mat[i][j] != mat[j][i]:
                raise fld.error(
                    value,
                    "symmetric",
                    f"entry [{i}][{j}] = {toml_text(value[i][j])} but [{j}][{i}] = "
                    f"{toml_text(value[j][i])}; write the same number in both",
                )


def _uncontrollable(A: np.ndarray, C: np.ndarray, unstable_only: bool, stack: str) -> list:
    """Eigenvalues s of A (unstable ones, or those on the imaginary axis) at which the PBH
    matrix ``[A - s I, C]`` (``stack="h"``) or ``[A - s I; C]`` (``"v"``) loses rank."""
    n = A.shape[0]
    scale = max(1.0, float(np.linalg.norm(A, 2)))
    bad = []
    for s in np.linalg.eigvals(A):
        if unstable_only:
            if s.real < -AXIS_RTOL * scale:
                continue
        elif abs(s.real) > AXIS_RTOL * scale:
            continue
        M = A - s * np.eye(n)
        pbh = np.hstack([M, C]) if stack == "h" else np.vstack([M, C])
        sv = np.linalg.svd(pbh, compute_uv=False)
        top = max(float(sv[0]), 1.0)
        if np.sum(sv > RANK_RTOL * top) < n:
            bad.append(complex(s))
    return bad


def lqr_expert(
    table: Any,
    states: Sequence[sp.Symbol],
    design: tuple[np.ndarray, np.ndarray, bool],
    path: str | None,
) -> tuple[list[sp.Expr], ExpertGain]:
    """``expert = "lqr"`` with ``[policy.lqr] Q, R``: ``K = R^-1 B^T P`` on the design model
    ``(A, B, linearised)``, checked (Q symmetric PSD, R symmetric PD, (A, B) stabilisable, no
    unobservable mode of (Q, A) on the imaginary axis, A - B K Hurwitz) and taken exactly."""
    A, B, linearised = design
    n, m = B.shape
    if table is None:
        raise SpecError(
            f'expert = "lqr" needs the table [policy.lqr] with the weights Q ({n} x {n}) and R '
            f"({m} x {m}); add\n[policy.lqr]\nQ = {_example(n, n, True)}\nR = "
            f"{_example(m, m, True)}",
            field="policy.lqr",
            path=path,
        )
    reader = TableReader("policy.lqr", table, _LQR_KEYS, path)
    for key, size in (("Q", n), ("R", m)):
        if key not in table:
            raise SpecError(
                f"missing key {key} in [policy.lqr]; write {key} = {_example(size, size, True)} "
                f"({_LQR_KEYS[key]})",
                field=f"policy.lqr.{key}",
                path=path,
            )
    fq, fr = reader.field_of("Q"), reader.field_of("R")
    shape_q = f"{n} x {n} (n x n: one row and one column per state)"
    shape_r = f"{m} x {m} (m x m: one row and one column per input)"
    Qx = read_number_matrix(table["Q"], fq, n, n, shape_q, identity_example=True)
    Rx = read_number_matrix(table["R"], fr, m, m, shape_r, identity_example=True)
    Q, R = _float(Qx), _float(Rx)
    _symmetric(Qx, fq, table["Q"])
    _symmetric(Rx, fr, table["R"])
    q_scale = float(np.max(np.abs(Q)))
    q_min = float(np.linalg.eigvalsh(Q)[0])
    if q_min < -PSD_RTOL * q_scale:
        raise fq.error(
            table["Q"],
            "positive semidefinite",
            f"its smallest eigenvalue is {q_min:.6g}; use e.g. Q = {_example(n, n, True)}",
        )
    r_scale = float(np.max(np.abs(R)))
    r_min = float(np.linalg.eigvalsh(R)[0])
    if not r_min > PD_RTOL * r_scale:
        raise fr.error(
            table["R"],
            "positive definite",
            f"its smallest eigenvalue is {r_min:.6g}; use e.g. R = {_example(m, m, True)}",
        )
    model = "the linearisation of f, g at x = 0" if linearised else "(A, B)"
    bad = _uncontrollable(A, B, True, "h")
    if bad:
        raise SpecError(
            f'expert = "lqr": {model} is not stabilisable: the mode(s) '
            f"{', '.join(_complex_text(z) for z in bad)} of A are not stable and not "
            "controllable from B (PBH test), so no gain u = -K x makes A - B K Hurwitz; add an "
            "input acting on that mode or change the model",
            field="policy.expert",
            path=path,
        )
    bad = _uncontrollable(A, Q, False, "v")
    if bad:
        raise fq.error(
            table["Q"],
            "a weight that sees every mode of A on the imaginary axis",
            f"the mode(s) {', '.join(_complex_text(z) for z in bad)} of A ({model}) are "
            "unobservable from Q, so the Riccati equation has no stabilising solution; weight "
            f"those states, e.g. Q = {_example(n, n, True)}",
        )
    import scipy.linalg  # scipy: 0.1 CPU-s to import, only an LQR expert needs it

    try:
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
        K = np.linalg.solve(R, B.T @ P)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SpecError(
            f'expert = "lqr": the Riccati equation on {model} with Q = {toml_text(table["Q"])}, '
            f"R = {toml_text(table['R'])} could not be solved ({exc}); scale the model or the "
            "weights, or give the gain as expert = { K = [[...]] }",
            field="policy.lqr",
            path=path,
        ) from None
    if not np.all(np.isfinite(K)):
        raise SpecError(
            f'expert = "lqr": the Riccati solver returned a non-finite gain on {model}; give the '
            "gain as expert = { K = [[...]] }",
            field="policy.lqr",
            path=path,
        )
    acl = A - B @ K
    eigs = _eigenvalues(acl)
    margin = HURWITZ_RTOL * max(1.0, float(np.linalg.norm(acl, 2)))
    if max(z.real for z in eigs) >= -margin:
        raise SpecError(
            f'expert = "lqr": the closed loop A - B K on {model} is not Hurwitz (eigenvalues '
            f"{', '.join(_complex_text(z) for z in eigs)}), so the Riccati solution is not "
            "stabilising; weight every state in Q (e.g. Q = I) or give the gain as "
            "expert = { K = [[...]] }",
            field="policy.lqr",
            path=path,
        )
    Km = sp.ImmutableMatrix([[sp.Rational(float(k)) for k in row] for row in K])
    expert = list(-Km * sp.Matrix(states))
    record = ExpertGain(
        K=Km,
        source="lqr",
        Q=tuple(tuple(float(v) for v in row) for row in Q),
        R=tuple(tuple(float(v) for v in row) for row in R),
        linearised=linearised,
        closed_loop_eigenvalues=eigs,
    )
    return expert, record
