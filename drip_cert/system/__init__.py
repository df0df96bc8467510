"""Describing a system: expressions, blocks, the System value object and TOML specs."""

from drip_cert.system.blocks import Block, load_mlp_block, mlp_block
from drip_cert.system.expr import parse_expression
from drip_cert.system.spec import Spec, load_spec, spec_from_dict
from drip_cert.system.system import NumericSystem, System

__all__ = [
    "Block",
    "NumericSystem",
    "Spec",
    "System",
    "load_mlp_block",
    "load_spec",
    "mlp_block",
    "parse_expression",
    "spec_from_dict",
]
