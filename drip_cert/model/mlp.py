"""Multi-layer perceptrons: the parameter pytree, evaluation, and the .npz/.json file format.

File format (shared by learned policies and by opaque blocks such as the paper's h(x)):

* ``NAME.npz`` (loaded with ``allow_pickle=False``): arrays ``W0, b0, W1, b1, ..., W{L-1}, b{L-1}``
  with ``W_i`` of shape ``(out_i, in_i)`` and ``b_i`` of shape ``(out_i,)``. Layer ``i < L-1`` is
  followed by the hidden activation; the last layer is affine, optionally followed by
  ``output_activation``.
* ``NAME.json`` (optional; architecture metadata): ``{"activation": "tanh",
  "output_activation": null, "activations": ["tanh", "tanh", "identity"], "sizes": [in, h1, ...,
  out]}`` (``activations``: one per layer, the output layer included; it wins over the other two
  when present). When absent the activation must be given by the caller.

Activations are the classes of :mod:`drip_cert.model.activations` (one registry, names such as
``"relu"``, ``"leaky_relu(0.2)"``); an MLP holds one per layer (:attr:`MLP.activations`). The
TaSIL lemma route needs a Lipschitz Jacobian (docs/math/tasil.md section 5): every activation
``smooth``; relu networks are certified through the routes that need none (docs/math/nonsmooth.md).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.model.activations import ACTIVATIONS as _REGISTRY
from drip_cert.model.activations import Activation, Identity, get_activation
from drip_cert.numerics.user_files import input_file, read_npz

ACTIVATIONS = tuple(_REGISTRY)
"""The registered activation names (:data:`drip_cert.model.activations.ACTIVATIONS`)."""
ActivationLike = str | Activation | None
_NARROW_INPUT = 8  # MLP.apply_jax writes a first layer this narrow as broadcast products


@dataclass(frozen=True)
class MLP:
    """A fully connected network ``x -> s_{L-1}(W_{L-1} s_{L-2}(... s_0(W_0 x + b_0) ...) +
    b_{L-1})`` with one activation ``s_k`` per layer.

    Parameters
    ----------
    weights, biases
        Tuples of numpy arrays, ``weights[i]`` of shape ``(out_i, in_i)``.
    activation
        Hidden activation (every layer but the last): a registry name or an
        :class:`~drip_cert.model.activations.Activation`.
    output_activation
        Optional activation after the last layer (``None`` for affine output).
    activations
        One activation per layer, the output layer included (wins over the two above). After
        construction it always holds the per-layer :class:`Activation` objects, and
        ``activation`` / ``output_activation`` hold their spec strings (``activation`` is
        ``"mixed"`` when the hidden layers differ).
    """

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    activation: str = "tanh"
    output_activation: str | None = None
    activations: tuple[Activation, ...] = ()

    def __post_init__(self) -> None:
        if len(self.weights) != len(self.biases) or not self.weights:
            raise SpecError("an MLP needs as many bias vectors as weight matrices, at least one")
        n = len(self.weights)
        if self.activations:
            acts = tuple(get_activation(a) for a in self.activations)
            if len(acts) != n:
                raise SpecError(
                    f"activations has {len(acts)} entries but the network has {n} layers "
                    "(give one per layer, the output layer included)"
                )
        else:
            hidden = get_activation(self.activation)
            acts = (hidden,) * (n - 1) + (get_activation(self.output_activation),)
        hid = {a.spec for a in acts[:-1]}
        if len(hid) == 1:
            object.__setattr__(self, "activation", acts[0].spec)
        elif len(hid) > 1:
            object.__setattr__(self, "activation", "mixed")
        else:  # one affine layer: keep the given hidden name (unused), validated
            object.__setattr__(self, "activation", get_activation(self.activation).spec)
        out = acts[-1]
        object.__setattr__(
            self, "output_activation", None if isinstance(out, Identity) else out.spec
        )
        object.__setattr__(self, "activations", acts)
        prev = None
        ws, bs = [], []
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            w = np.asarray(w, dtype=np.float64)
            b = np.asarray(b, dtype=np.float64)
            if w.ndim != 2 or b.shape != (w.shape[0],):
                raise SpecError(
                    f"layer {i}: W{i} must be (out, in) and b{i} (out,), "
                    f"got {w.shape} and {b.shape}"
                )
            if prev is not None and w.shape[1] != prev:
                raise SpecError(
                    f"layer {i}: W{i} expects {w.shape[1]} inputs but layer {i - 1} gives {prev}"
                )
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise SpecError(f"layer {i}: weights contain NaN or inf")
            units = acts[i].units
            if units is not None and units != w.shape[0]:
                raise SpecError(
                    f"layer {i}: activation {acts[i]} has {units} per-unit parameters but the "
                    f"layer has {w.shape[0]} units"
                )
            prev = w.shape[0]
            w.setflags(write=False)
            b.setflags(write=False)
            ws.append(w)
            bs.append(b)
        object.__setattr__(self, "weights", tuple(ws))
        object.__setattr__(self, "biases", tuple(bs))

    @property
    def in_dim(self) -> int:
        return int(self.weights[0].shape[1])

    @property
    def out_dim(self) -> int:
        return int(self.weights[-1].shape[0])

    @property
    def sizes(self) -> tuple[int, ...]:
        return (self.in_dim, *(int(w.shape[0]) for w in self.weights))

    @property
    def smooth(self) -> bool:
        """True when every activation has a Lipschitz derivative (the Jacobian is Lipschitz)."""
        return all(a.smooth for a in self.activations)

    @property
    def activation_specs(self) -> tuple[str, ...]:
        """The spec string of each layer's activation (output layer included)."""
        return tuple(a.spec for a in self.activations)

    @property
    def n_params(self) -> int:
        return int(sum(w.size + b.size for w, b in zip(self.weights, self.biases)))

    def params(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The parameter pytree ``[(W0, b0), ...]`` used by :func:`apply_params`."""
        return [(w, b) for w, b in zip(self.weights, self.biases)]

    def apply_np(self, x: np.ndarray) -> np.ndarray:
        """Evaluate with numpy on ``x`` of shape ``(..., in_dim)``."""
        return apply_params(self.params(), np.asarray(x, dtype=np.float64), self.activations, xp=np)

    def apply_jax(self, x):
        """Evaluate with jax.numpy on ``x`` of shape ``(..., in_dim)`` (traceable).

        With ``in_dim <= 8`` and a hidden layer, the first layer is written as ``in_dim``
        broadcast multiply-adds instead of a matrix product (``apply_params(...,
        narrow_first=True)``): XLA's CPU backend runs a product with such a short inner dimension
        far below its FMA throughput, while the broadcast form fuses with the bias and the
        activation. Same value up to summation order; the Monte-Carlo benchmark measured ~10 ns
        less per path-step (of ~230) on the 4-64-64-4 policy. Training differentiates
        :func:`apply_params` with the plain product (the broadcast form was ~25 % slower there).
        """
        from drip_cert._jax import jnp  # jax: keep off the CLI start-up path

        params = [(jnp.asarray(w), jnp.asarray(b)) for w, b in self.params()]
        return apply_params(params, x, self.activations, xp=jnp, narrow_first=True)

    def save(self, path: str | Path) -> None:
        """Write ``path`` (.npz) and the metadata ``path.with_suffix('.json')`` atomically."""
        save_mlp(self, path)


def activation_fn(name: ActivationLike, xp):
    """The activation ``name`` for the array module ``xp`` (numpy or jax.numpy)."""
    act = get_activation(name)
    return lambda z: act.apply(z, xp)


def layer_activations(
    n_layers: int,
    activation: ActivationLike | Sequence[ActivationLike],
    output_activation: ActivationLike = None,
) -> tuple[Activation, ...]:
    """One activation per layer: ``activation`` for the hidden layers and ``output_activation``
    for the last, or ``activation`` itself when it is a per-layer sequence."""
    if isinstance(activation, (list, tuple)):
        acts = tuple(get_activation(a) for a in activation)
        if len(acts) != n_layers:
            raise SpecError(f"{len(acts)} activations given for {n_layers} layers")
        return acts
    hidden = get_activation(activation)  # type: ignore[arg-type]
    return (hidden,) * (n_layers - 1) + (get_activation(output_activation),)


def apply_params(
    params,
    x,
    activation: ActivationLike | Sequence[ActivationLike],
    output_activation: ActivationLike = None,
    xp=np,
    narrow_first: bool = False,
):
    """Forward pass of the parameter pytree ``[(W, b), ...]`` on ``x`` of shape ``(..., in)``.

    ``activation``: the hidden activation (then ``output_activation`` is the last layer's) or
    a sequence of one activation per layer. ``narrow_first``: write a first HIDDEN layer with
    at most ``_NARROW_INPUT`` inputs as broadcast multiply-adds (see :meth:`MLP.apply_jax`);
    same value up to summation order.
    """
    acts = layer_activations(len(params), activation, output_activation)
    h = x
    last = len(params) - 1
    for i, (w, b) in enumerate(params):
        if i == 0 and narrow_first and i < last and w.shape[1] <= _NARROW_INPUT:
            z = b + h[..., 0:1] * w[:, 0]
            for k in range(1, w.shape[1]):
                z = z + h[..., k : k + 1] * w[:, k]
            h = z
        else:
            h = h @ w.T + b
        if not isinstance(acts[i], Identity):
            h = acts[i].apply(h, xp)
    return h


def init_mlp(
    sizes: Sequence[int],
    rng: np.random.Generator,
    activation: str = "tanh",
    output_activation: str | None = None,
    scale: float = 1.0,
) -> MLP:
    """Random MLP with LeCun-normal weights (``scale / sqrt(fan_in)``) and zero biases."""
    if len(sizes) < 2 or any(int(s) < 1 for s in sizes):
        raise SpecError(f"MLP sizes must be >= 2 positive integers, got {list(sizes)}")
    ws, bs = [], []
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        ws.append(rng.normal(size=(fan_out, fan_in)) * scale / np.sqrt(fan_in))
        bs.append(np.zeros(fan_out))
    return MLP(tuple(ws), tuple(bs), activation, output_activation)


def save_mlp(mlp: MLP, path: str | Path) -> None:
    """Save ``mlp`` as ``path`` (.npz) plus ``.json`` metadata; each written atomically."""
    path = Path(path)
    # keys W{i}/b{i} never clash with np.savez's own keywords (file, allow_pickle); the values are
    # typed Any because mypy matches **arrays also against ``allow_pickle: bool``
    arrays: dict[str, Any] = {}
    for i, (w, b) in enumerate(zip(mlp.weights, mlp.biases)):
        arrays[f"W{i}"] = w
        arrays[f"b{i}"] = b
    meta = {
        "activation": mlp.activation,
        "output_activation": mlp.output_activation,
        "activations": list(mlp.activation_specs),
        "sizes": list(mlp.sizes),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(path)
    jtmp = path.with_suffix(".json.tmp")
    jtmp.write_text(json.dumps(meta, indent=2) + "\n")
    jtmp.replace(path.with_suffix(".json"))


def load_mlp(
    path: str | Path,
    activation: str | Sequence[str] | None = None,
    output_activation: str | None = None,
    expect_in: int | None = None,
    expect_out: int | None = None,
    field: str | None = None,
) -> MLP:
    """Load an MLP saved by :func:`save_mlp` (``allow_pickle=False``).

    ``activation`` (one name for the hidden layers with an affine output, or a list with one
    entry per layer, the output layer included) overrides the JSON metadata; one of the two
    must be present.
    ``expect_in``/``expect_out`` check the declared shape. Every problem is a
    :class:`~drip_cert.errors.SpecError` naming the file and what to fix.
    """
    path = input_file(path, "weights file", field=field)
    meta: dict = {}
    mpath = path.with_suffix(".json")
    if mpath.is_file():
        try:
            meta = json.loads(mpath.read_text())
        except (OSError, ValueError) as exc:
            raise SpecError(
                f"metadata {str(mpath)!r} is not valid JSON: {exc}", field=field
            ) from None
        if not isinstance(meta, dict):
            raise SpecError(f"metadata {str(mpath)!r} must be a JSON object", field=field)
    files = read_npz(path, "weights file", field=field)
    n_layers = 0
    while f"W{n_layers}" in files:
        n_layers += 1
    if n_layers == 0:
        raise SpecError(
            f"weights file {str(path)!r} has no array 'W0' (expected W0, b0, W1, b1, ...)",
            field=field,
        )
    missing = [f"b{i}" for i in range(n_layers) if f"b{i}" not in files]
    if missing:
        raise SpecError(f"weights file {str(path)!r} lacks {missing}", field=field)
    act = activation or meta.get("activations") or meta.get("activation")
    if act is None:
        raise SpecError(
            f"no activation for {str(path)!r}: give 'activation' or a .json file", field=field
        )
    out_act = output_activation if output_activation is not None else meta.get("output_activation")
    try:
        mlp = MLP(
            tuple(files[f"W{i}"] for i in range(n_layers)),
            tuple(files[f"b{i}"] for i in range(n_layers)),
            activations=layer_activations(n_layers, act, out_act),
        )
    except SpecError as exc:
        raise SpecError(f"weights file {str(path)!r}: {exc}", field=field) from None
    if expect_in is not None and mlp.in_dim != expect_in:
        raise SpecError(
            f"weights file {str(path)!r} takes {mlp.in_dim} inputs but the block "
            f"declares {expect_in}",
            field=field,
        )
    if expect_out is not None and mlp.out_dim != expect_out:
        raise SpecError(
            f"weights file {str(path)!r} gives {mlp.out_dim} outputs but the block "
            f"declares {expect_out}",
            field=field,
        )
    return mlp


def mlp_from_params(
    params,
    activation: ActivationLike | Sequence[ActivationLike] = "tanh",
    output_activation: ActivationLike = None,
) -> MLP:
    """The :class:`MLP` value object of a parameter pytree ``[(W0, b0), (W1, b1), ...]``.

    ``params`` may hold numpy or jax arrays (e.g. the result of training); they are copied to
    read-only float64 numpy arrays, so the returned MLP is saved by :func:`save_mlp` in the
    standard ``.npz``/``.json`` format. Inverse of :func:`jax_params`.
    """
    try:
        ws = tuple(np.asarray(w, dtype=np.float64) for w, _ in params)
        bs = tuple(np.asarray(b, dtype=np.float64) for _, b in params)
    except (TypeError, ValueError) as exc:
        raise SpecError(
            f"MLP parameters must be a sequence of (W, b) pairs of arrays: {exc}"
        ) from None
    return MLP(ws, bs, activations=layer_activations(len(ws), activation, output_activation))


def jax_params(mlp: MLP) -> list:
    """The parameter pytree ``[(W0, b0), ...]`` of ``mlp`` as jax arrays (inverse of
    :func:`mlp_from_params`), ready for :func:`apply_params` with ``xp=jax.numpy``."""
    from drip_cert._jax import jnp  # jax: keep off the CLI start-up path

    return [(jnp.asarray(w), jnp.asarray(b)) for w, b in mlp.params()]
