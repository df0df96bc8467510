"""safetensors networks: a PyTorch ``nn.Sequential`` state_dict or Flax ``Dense`` parameters.

Layouts (:func:`read_safetensors`; the separator may be ``.`` or ``/``):

* PyTorch ``nn.Sequential`` of ``Linear`` layers (activations in between carry no tensors):
  ``PREFIX0.weight`` of shape ``(out, in)`` and ``PREFIX0.bias``, then ``PREFIX2.weight``, ...,
  the layers ordered by their integer index (an optional common prefix such as ``net.`` is
  allowed).
* Flax ``nn.Dense`` parameters: ``Dense_0.kernel`` of shape ``(in, out)`` (input-major, so the
  weight is its transpose) and ``Dense_0.bias``, ``Dense_1...``; also flattened with a
  ``params.`` prefix (``params.Dense_0.kernel``).

The activations are not in the file: the block table gives them (``activation = "relu"`` for the
hidden layers with an affine output, or a list with one entry per layer, output included).
A missing tensor, a shape that does not chain, a non-float dtype or an unknown tensor is a
:class:`~drip_cert.errors.SpecError` naming the file and the tensor.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from safetensors.numpy import load_file, save_file

from drip_cert.errors import SpecError
from drip_cert.model.mlp import MLP, layer_activations
from drip_cert.numerics.user_files import input_file, reading

__all__ = ["read_safetensors", "write_safetensors"]

_TORCH = re.compile(r"^(?P<prefix>(?:.*\.)?)(?P<idx>\d+)\.(?P<kind>weight|bias)$")
_FLAX = re.compile(r"^(?P<prefix>(?:.*\.)?)Dense_(?P<idx>\d+)\.(?P<kind>kernel|bias)$")


def _err(path: Path, msg: str, fld: str | None) -> SpecError:
    return SpecError(f"safetensors file {str(path)!r}: {msg}", field=fld)


def read_safetensors(
    path: str | Path,
    activation: str | Sequence[str] | None,
    expect_in: int | None = None,
    expect_out: int | None = None,
    field: str | None = None,
) -> MLP:
    """Read the network ``path`` (see the module docstring) with the given activations."""
    p = input_file(path, "safetensors file", field=field)
    with reading(p, "safetensors file"):
        try:
            raw = load_file(str(p))
        except Exception as exc:  # safetensors raises its own SafetensorError and others
            raise _err(p, f"cannot be read ({type(exc).__name__}: {exc})", field) from exc
    tensors = {k.replace("/", "."): v for k, v in raw.items()}
    if not tensors:
        raise _err(p, "holds no tensors", field)
    layout, pattern = ("torch", _TORCH)
    if all(_FLAX.match(k) for k in tensors):
        layout, pattern = ("flax", _FLAX)
    matches = {k: pattern.match(k) for k in tensors}
    unknown = sorted(k for k, m in matches.items() if m is None)
    if unknown:
        raise _err(
            p,
            f"tensor(s) {unknown[:5]} are not Linear/Dense parameters (expected "
            "'0.weight', '0.bias', '2.weight', ... or 'Dense_0.kernel', 'Dense_0.bias', ...); "
            "only fully connected networks are supported",
            field,
        )
    prefixes = {m.group("prefix") for m in matches.values() if m is not None}
    if len(prefixes) != 1:
        raise _err(p, f"tensors under several prefixes {sorted(prefixes)}: one network only", field)
    prefix = prefixes.pop()
    wkey = "weight" if layout == "torch" else "kernel"
    idx = sorted({int(m.group("idx")) for m in matches.values() if m is not None})
    ws, bs = [], []
    prev_out: int | None = None
    for i in idx:
        name_w = (f"{prefix}{i}.{wkey}") if layout == "torch" else f"{prefix}Dense_{i}.{wkey}"
        name_b = (f"{prefix}{i}.bias") if layout == "torch" else f"{prefix}Dense_{i}.bias"
        for name in (name_w, name_b):
            if name not in tensors:
                raise _err(p, f"tensor {name!r} is missing (layer {i})", field)
            if not np.issubdtype(tensors[name].dtype, np.floating):
                raise _err(
                    p, f"tensor {name!r} has dtype {tensors[name].dtype}; only floats", field
                )
            if not np.all(np.isfinite(tensors[name])):
                raise _err(p, f"tensor {name!r} contains NaN or inf", field)
        w = np.asarray(tensors[name_w], dtype=np.float64)
        b = np.asarray(tensors[name_b], dtype=np.float64)
        if w.ndim != 2:
            raise _err(p, f"tensor {name_w!r} must be a matrix, has shape {w.shape}", field)
        if layout == "flax":
            w = w.T  # kernel (in, out) -> weight (out, in)
        if b.shape != (w.shape[0],):
            raise _err(p, f"tensor {name_b!r} has shape {b.shape}, expected ({w.shape[0]},)", field)
        if prev_out is not None and w.shape[1] != prev_out:
            raise _err(
                p,
                f"tensor {name_w!r} takes {w.shape[1]} inputs but the layer before gives "
                f"{prev_out}",
                field,
            )
        prev_out = w.shape[0]
        ws.append(w)
        bs.append(b)
    if activation is None:
        raise _err(
            p,
            "a safetensors file has no activations: give 'activation' in the block table "
            '(e.g. "relu", or ["relu", "relu", "identity"])',
            field,
        )
    try:
        mlp = MLP(tuple(ws), tuple(bs), activations=layer_activations(len(ws), activation))
    except SpecError as exc:
        raise _err(p, str(exc), field) from None
    for what, want, got in (
        ("inputs", expect_in, mlp.in_dim),
        ("outputs", expect_out, mlp.out_dim),
    ):
        if want is not None and want != got:
            raise _err(p, f"the network has {got} {what} but the block declares {want}", field)
    return mlp


def write_safetensors(mlp: MLP, path: str | Path, layout: str = "torch") -> Path:
    """Write ``mlp``'s parameters in the PyTorch ``nn.Sequential`` layout (``Linear`` at even
    indices) or the Flax ``Dense_i`` layout (``layout="flax"``)."""
    out: dict[str, np.ndarray] = {}
    for k, (w, b) in enumerate(zip(mlp.weights, mlp.biases)):
        if layout == "torch":
            out[f"{2 * k}.weight"], out[f"{2 * k}.bias"] = np.ascontiguousarray(w), b.copy()
        else:
            out[f"Dense_{k}.kernel"], out[f"Dense_{k}.bias"] = np.ascontiguousarray(w.T), b.copy()
    p = Path(path)
    save_file(out, str(p))
    return p
