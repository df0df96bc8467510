"""The Monte-Carlo engine (layer 6): the four processes of the DRIP paper on one numeric view.

Modules: :mod:`~drip_cert.sim.config` (settings, scenario and gap names, status codes),
:mod:`~drip_cert.sim.noise` (counter-based normals), :mod:`~drip_cert.sim.kernel` (the jitted
step, a block of recorded times per call), :mod:`~drip_cert.sim.accumulate` (the statistics of the
absorbed chunks), :mod:`~drip_cert.sim.resume` (run directories),
:mod:`~drip_cert.sim.result` (``SimResult``) and :mod:`~drip_cert.sim.engine` (the driver
``simulate``). Nothing here imports the bounds.
"""
