"""The spec layer: ``load_spec`` reads a TOML spec into a :class:`Spec` (a model plus its settings).

Every table is validated when the spec is loaded (:mod:`drip_cert.spec.settings`).
"""

from drip_cert.spec.load import Spec, SpecSource, as_spec, load_spec, spec_from_dict

__all__ = ["Spec", "SpecSource", "as_spec", "load_spec", "spec_from_dict"]
