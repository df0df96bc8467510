"""Sound interval enclosures of block values and Jacobian entries, for the interval analyses.

:func:`block_enclose_callback` returns the ``enclose`` callback that
:mod:`drip_cert.numerics.interval` calls for every block application: for an MLP block it
encloses the output (or a Jacobian entry) over the box of the arguments' enclosures by interval
bound propagation (:func:`drip_cert.analysis.networks.mlp.enclose_output`,
:func:`~drip_cert.analysis.networks.mlp.enclose_jacobian`, outward rounded). Blocks that are not
MLPs
and Hessian entries have no enclosure here: the callback returns ``None`` and the analysis falls
back to its sampled estimate, labelled as such.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from drip_cert.analysis.networks.mlp import enclose_jacobian, enclose_output
from drip_cert.model.blocks import Block, BlockFunction


def block_enclose_callback(blocks: Mapping[str, Block]) -> Callable:
    """The ``enclose(node, arg_intervals) -> (lo, hi) | None`` callback for ``blocks``."""

    def enclose(node, args):
        if not isinstance(node, BlockFunction):
            return None
        block = blocks.get(node.block_name)
        if block is None or block.mlp is None or len(node.deriv) > 1:
            return None
        lo = np.array([a[0] for a in args], dtype=float)
        hi = np.array([a[1] for a in args], dtype=float)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return None
        j = node.out_index
        if not node.deriv:
            ylo, yhi = enclose_output(block.mlp, lo, hi)
            return float(ylo[j]), float(yhi[j])
        i = node.deriv[0]
        jlo, jhi = enclose_jacobian(block.mlp, lo, hi)
        return float(jlo[j, i]), float(jhi[j, i])

    return enclose
