"""Fingerprints of what a certificate certifies: the policy and the deployed design.

Recorded data (``docs/data_format.md``) are evidence about one policy and one L1-DRAC design;
checked against the certificate of another they prove nothing about it. A :class:`Fingerprint`
ties them together: two short SHA-256 digests, each of a canonical byte serialisation of

* ``policy``: the expert ``pi*`` and the learned policy ``pi_IL`` (their sympy expressions), the
  state and input names, and every block the two apply (an MLP's activations and the bytes of
  its float64 weights and biases);
* ``design``: what the deployed L1-DRAC controller runs besides the policy: the design
  parameters ``(omega, lambda_s, T_s)`` (``None`` without a feasible design), the nominal
  model ``f``, ``g`` of its predictor (15c) and adaptation law (15b) with the blocks they apply,
  and the coordinates ``Theta`` of a certificate in ``z = Theta x`` (``x`` otherwise).

Canonical means: every field is fed to the hash with a tag and a length prefix (no separator
can be forged), floats as their IEEE-754 binary64 bytes (little-endian, never a decimal
``repr``), arrays as their shape and little-endian C-order float64 bytes, expressions as
:func:`sympy.srepr` (sympy orders the arguments of sums and products by structure, not by hash;
floats in expressions print with the 17 digits that identify the double), blocks sorted by name.
No dict order, no timing, no address enters: the same system gives the same digests in every
process and on every machine (a test runs two processes with different hash seeds), and a one-ulp
change of one weight or design parameter gives another.

What does not change what runs is left out on purpose: the uncertainty model, the initial law,
the horizon, the settings, the claims (``delta``, ``p``) and every timing. Data recorded with the
same policy and controller remain samples of the same processes when those change. An opaque
block (a Python callable, not an MLP) enters by its name, sizes and source only: its function
cannot be hashed.
"""

from __future__ import annotations

import hashlib
import re
import struct
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import sympy as sp

from drip_cert.model.blocks import block_applications

if TYPE_CHECKING:
    from drip_cert.model.system import System

__all__ = [
    "HEX_DIGITS",
    "SCHEME",
    "Fingerprint",
    "design_fingerprint",
    "fingerprint_of",
    "policy_fingerprint",
]

SCHEME = "drip-cert-fingerprint/1"
"""Name and version of the serialisation; hashed first, so a new layout gives new digests."""

HEX_DIGITS = 16
"""Hex digits kept of each SHA-256 digest (64 bits: an accidental match of two different
policies has probability 2^-64; the fingerprint guards against mix-ups, not forgery)."""

PARTS = ("policy", "design")
"""The two parts of a fingerprint, in the order they are written."""

_HEX = re.compile(rf"[0-9a-f]{{{HEX_DIGITS}}}")


@dataclass(frozen=True)
class Fingerprint:
    """The ``policy`` and ``design`` digests of a certificate or of recorded data.

    Attributes
    ----------
    policy
        :data:`HEX_DIGITS` lowercase hex digits (:func:`policy_fingerprint`).
    design
        The same for :func:`design_fingerprint`, or ``None`` where only a policy is known (the
        fingerprint of :func:`drip_cert.deploy.learned_policy`).

    ``str(fp)`` is the text recorded data carry, ``"policy=<hex>, design=<hex>"`` (the ``.npz``
    entry ``fingerprint``, the CSV comment ``# fingerprint: ...``); :meth:`parse` reads it back.
    ``numpy.savez(..., fingerprint=fp)`` stores that text as a string array.
    """

    policy: str
    design: str | None = None

    def __post_init__(self) -> None:
        for name in PARTS:
            v = getattr(self, name)
            if v is None and name == "design":
                continue
            if not isinstance(v, str) or not _HEX.fullmatch(v):
                raise ValueError(
                    f"the {name} part must be {HEX_DIGITS} lowercase hex digits, got {v!r}"
                )

    def __str__(self) -> str:
        return ", ".join(f"{k}={getattr(self, k)}" for k in PARTS if getattr(self, k) is not None)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        """``numpy.asarray(fp)``: the text as a 0-d string array (what ``numpy.savez`` stores)."""
        return np.array(str(self), dtype=dtype)

    def to_dict(self) -> dict[str, Any]:
        """``{"policy": hex, "design": hex or None, "scheme": SCHEME}`` (the certificate key)."""
        return {"policy": self.policy, "design": self.design, "scheme": SCHEME}

    @classmethod
    def parse(cls, text: str) -> Fingerprint:
        """Read ``"policy=<hex>, design=<hex>"`` (``design`` optional, any order).

        Raises
        ------
        ValueError
            Saying what was expected, for any other text.
        """
        parts: dict[str, str] = {}
        for item in (s.strip() for s in str(text).split(",")):
            key, sep, val = item.partition("=")
            key = key.strip()
            if not sep or key not in PARTS or key in parts:
                raise ValueError(
                    f"expected 'policy=<{HEX_DIGITS} hex digits>, design=<{HEX_DIGITS} hex "
                    f"digits>' (str(controller.fingerprint)), got {text!r}"
                )
            parts[key] = val.strip()
        if "policy" not in parts:
            raise ValueError(f"no 'policy=' part in {text!r}")
        return cls(policy=parts["policy"], design=parts.get("design"))


# ---------------------------------------------------------------------- serialisation
class _Hasher:
    """SHA-256 over tagged, length-prefixed fields (an unambiguous byte serialisation)."""

    def __init__(self, part: str) -> None:
        self._h = hashlib.sha256()
        self.text(SCHEME, "scheme")
        self.text(part, "part")

    def _field(self, tag: str, payload: bytes) -> None:
        t = tag.encode()
        self._h.update(struct.pack("<Q", len(t)) + t + struct.pack("<Q", len(payload)) + payload)

    def text(self, value: str, tag: str) -> None:
        self._field(tag, value.encode("utf-8"))

    def number(self, value: float | None, tag: str) -> None:
        self._field(tag, b"none" if value is None else struct.pack("<d", float(value)))

    def array(self, value: Any, tag: str) -> None:
        a = np.ascontiguousarray(np.asarray(value, dtype="<f8"))
        self.text(repr(tuple(int(d) for d in a.shape)), tag + ".shape")
        self._field(tag + ".data", a.tobytes(order="C"))

    def exprs(self, mat: sp.MatrixBase, tag: str) -> None:
        self.text(repr(tuple(int(d) for d in mat.shape)), tag + ".shape")
        for i, e in enumerate(mat):
            self.text(sp.srepr(e), f"{tag}[{i}]")

    def blocks(self, system: System, mats: Iterable[sp.MatrixBase | None]) -> None:
        used = sorted(
            {a.block_name for m in mats if m is not None for e in m for a in block_applications(e)}
        )
        self.text(repr(used), "blocks")
        for name in used:
            b = system.blocks[name]
            tag = f"block.{name}"
            self.text(f"{b.in_dim}->{b.out_dim}", tag + ".sizes")
            if b.mlp is None:
                self.text("opaque:" + b.source, tag + ".kind")
                continue
            mlp = b.mlp
            kind = f"mlp:{mlp.activation}:{mlp.output_activation}"
            if mlp.activation == "mixed":  # per-layer activations (uniform ones hash as before)
                kind = "mlp:" + ",".join(mlp.activation_specs)
            self.text(kind, tag + ".kind")
            for i, (w, bias) in enumerate(zip(mlp.weights, mlp.biases, strict=True)):
                self.array(w, f"{tag}.W{i}")
                self.array(bias, f"{tag}.b{i}")

    def hexdigest(self) -> str:
        return self._h.hexdigest()[:HEX_DIGITS]


def policy_fingerprint(system: System) -> str:
    """The ``policy`` digest of ``system`` (in the user's coordinates ``x``).

    Hashes the state and input names, the expert ``pi*`` and the learned ``pi_IL`` (``None``
    hashed as such) and the blocks they apply; see the module docstring.
    """
    h = _Hasher("policy")
    h.text(repr([s.name for s in system.states]), "states")
    h.text(repr(list(system.inputs)), "inputs")
    h.exprs(system.expert, "expert")
    if system.learned is None:
        h.text("none", "learned")
    else:
        h.exprs(system.learned, "learned")
    h.blocks(system, (system.expert, system.learned))
    return h.hexdigest()


def design_fingerprint(
    system: System,
    l1_design: tuple[float, float, float] | None,
    theta: np.ndarray | None = None,
) -> str:
    """The ``design`` digest: what the deployed L1-DRAC controller runs besides the policy.

    Parameters
    ----------
    system
        The system in the user's coordinates ``x``: its ``f`` and ``g`` (and the blocks they
        apply) enter the controller's predictor (15c) and adaptation law (15b).
    l1_design
        ``(omega, lambda_s, T_s)`` of the certified design, or ``None`` (no feasible design).
    theta
        ``Theta`` of a certificate in ``z = Theta x``, or ``None`` (computed in ``x``).
    """
    h = _Hasher("design")
    h.text(repr([s.name for s in system.states]), "states")
    h.text(system.t.name, "time")
    h.exprs(system.f, "f")
    h.exprs(system.g, "g")
    h.blocks(system, (system.f, system.g))
    if l1_design is None:
        h.text("none", "l1drac")
    else:
        for name, v in zip(("omega", "lambda_s", "Ts"), l1_design, strict=True):
            h.number(v, f"l1drac.{name}")
    if theta is None:
        h.text("x", "coordinates")
    else:
        h.array(theta, "coordinates.theta")
    return h.hexdigest()


def fingerprint_of(
    system: System,
    l1_design: tuple[float, float, float] | None,
    theta: np.ndarray | None = None,
) -> Fingerprint:
    """The :class:`Fingerprint` of a certificate of ``system`` (in ``x``) with this design."""
    return Fingerprint(
        policy=policy_fingerprint(system), design=design_fingerprint(system, l1_design, theta)
    )
