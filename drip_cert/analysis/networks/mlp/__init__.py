"""Bounds of MLPs, by concept: Lipschitz constants of the network and of its Jacobian
(:mod:`.lipschitz`), LipSDP and the best Lipschitz bound (:mod:`.lipsdp`), interval enclosures
of value and Jacobian (:mod:`.enclosures`), and the fast centred enclosures with Hessians
(:mod:`.derivatives`). The activations themselves are :mod:`drip_cert.model.activations`; the
vectorised interval arithmetic is :mod:`drip_cert.numerics.interval_np`."""

from drip_cert.analysis.networks.mlp.derivatives import DerivativeEnclosure as DerivativeEnclosure
from drip_cert.analysis.networks.mlp.derivatives import enclose_derivatives as enclose_derivatives
from drip_cert.analysis.networks.mlp.derivatives import (
    enclose_jacobian_centred as enclose_jacobian_centred,
)
from drip_cert.analysis.networks.mlp.enclosures import check_box as check_box
from drip_cert.analysis.networks.mlp.enclosures import enclose_activation as enclose_activation
from drip_cert.analysis.networks.mlp.enclosures import (
    enclose_activation_prime as enclose_activation_prime,
)
from drip_cert.analysis.networks.mlp.enclosures import enclose_jacobian as enclose_jacobian
from drip_cert.analysis.networks.mlp.enclosures import enclose_output as enclose_output
from drip_cert.analysis.networks.mlp.enclosures import jacobian_np as jacobian_np
from drip_cert.analysis.networks.mlp.lipschitz import activation_bounds as activation_bounds
from drip_cert.analysis.networks.mlp.lipschitz import (
    jacobian_lipschitz_bound as jacobian_lipschitz_bound,
)
from drip_cert.analysis.networks.mlp.lipschitz import lipschitz_product as lipschitz_product
from drip_cert.analysis.networks.mlp.lipsdp import LipSDPResult as LipSDPResult
from drip_cert.analysis.networks.mlp.lipsdp import lipschitz_bound as lipschitz_bound
from drip_cert.analysis.networks.mlp.lipsdp import lipschitz_lipsdp as lipschitz_lipsdp
