"""Analysis (layer 5): bounds on properties of a system, in four families.

* :mod:`drip_cert.analysis.contraction` -- log norms, contraction rates and their routes, LMI
  metrics, coordinate changes, forward-invariant sets;
* :mod:`drip_cert.analysis.growth` -- growth, Lipschitz and Hoelder constants, the input and
  uncertainty constants, the nominal process's constants;
* :mod:`drip_cert.analysis.networks` -- enclosures of MLPs and blocks, policy regularity;
* :mod:`drip_cert.analysis.iss` -- delta-ISS gains.
"""
