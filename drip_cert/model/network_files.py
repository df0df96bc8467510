"""Network files by extension: ``.onnx`` (:mod:`~drip_cert.model.onnx_io`), ``.safetensors``
(:mod:`~drip_cert.model.safetensors_io`) and ``.npz`` (:func:`~drip_cert.model.mlp.load_mlp`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from drip_cert.errors import SpecError
from drip_cert.model.mlp import MLP, load_mlp
from drip_cert.model.safetensors_io import read_safetensors
from drip_cert.numerics.user_files import input_file

__all__ = ["NETWORK_FORMATS", "load_network"]

NETWORK_FORMATS = (".onnx", ".safetensors", ".npz")
"""The extensions :func:`load_network` reads."""


def load_network(
    path: str | Path,
    activation: str | Sequence[str] | None = None,
    expect_in: int | None = None,
    expect_out: int | None = None,
    field: str | None = None,
) -> MLP:
    """The network in ``path``, its format from the extension (see the module docstring).

    ``activation``: for ``.safetensors`` (required) and ``.npz`` (else from the ``.json``
    metadata) one name for the hidden layers with an affine output, or one per layer; an ONNX
    graph carries its own activations, so giving one is an error.
    """
    if Path(path).is_dir():  # a directory has no format to name: say what it is
        input_file(path, "weights file", field=field)
    suffix = Path(path).suffix.lower()
    if suffix == ".onnx":
        if activation is not None:
            raise SpecError(
                f"{str(path)!r}: an ONNX graph defines its own activations; remove 'activation'",
                field=field,
            )
        from drip_cert.model.onnx_io import read_onnx  # onnx: only an .onnx file needs it

        return read_onnx(path, expect_in, expect_out, field=field)
    if suffix == ".safetensors":
        return read_safetensors(path, activation, expect_in, expect_out, field=field)
    if suffix == ".npz":
        return load_mlp(
            path, activation=activation, expect_in=expect_in, expect_out=expect_out, field=field
        )
    raise SpecError(
        f"weights file {str(path)!r} has extension {suffix or '(none)'!r}; give one of "
        f"{', '.join(NETWORK_FORMATS)}",
        field=field,
    )
