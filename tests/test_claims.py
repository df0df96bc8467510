"""One reading of a certificate's claims (``Certificate.claims``) for both validations.

``validate`` (simulated runs) and ``validate --data`` (recorded runs) check the same numbers:
both must read them from the one :class:`~drip_cert.bounds.certificate.Claims` object, never
from the certificate's fields on their own.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from drip_cert.bounds.certificate import Claims
from tests.helpers import example_spec

SEED = 0
N_PATHS = 8  # paths of the recorded data: a few, enough for the checks' sample variances


class _Stop(Exception):
    """Raised by the spy once the checks' inputs are known (the rest is not under test)."""


def _sentinel() -> Claims:
    # values no certificate field of the stub holds: only a read of the claims can give them
    return Claims(
        rho_tasil=0.123,
        delta_tasil=0.456,
        rho_l1=0.0789,
        p=3,
        kappa=0.0321,
        delta_l1=0.0654,
        design=(31.0, 7.0, 0.002),
        rho_sde=None,
        rho=0.2019,
    )


def _stub(claims: Claims) -> SimpleNamespace:
    # no rho_tasil / rho_l1 / tasil / design here: a function reading them directly fails
    return SimpleNamespace(
        claims=lambda: claims, coordinates=None, l1=None, fingerprint=None, to_dict=dict
    )


def _spy(seen: list[dict]):
    def checks_from_result(res, **kw):
        seen.append({k: kw[k] for k in CLAIMED})
        raise _Stop

    return checks_from_result


CLAIMED = ("rho_tasil", "delta_tasil", "rho_l1", "p", "kappa", "delta_l1")


def test_validate_and_validate_data_read_the_same_claims(monkeypatch, tmp_path):
    import drip_cert.validate.data as data_mod
    import drip_cert.validate.run as run_mod

    claims = _sentinel()
    seen: list[dict] = []
    monkeypatch.setattr(run_mod, "checks_from_result", _spy(seen))
    monkeypatch.setattr(data_mod, "checks_from_result", _spy(seen))
    monkeypatch.setattr(run_mod, "run_scenarios", lambda *a, **kw: SimpleNamespace())

    text = example_spec("infeasible_2d").read_text()
    text = text.replace(
        'expert = ["-x1 - 2*x2"]', 'expert = ["-x1 - 2*x2"]\nlearned = ["-1.01*x1 - 2*x2"]'
    )
    spec = tmp_path / "learned.toml"
    spec.write_text(text)
    with pytest.raises(_Stop):
        run_mod.validate(str(spec), _stub(claims), paths=4, seed=SEED)

    rng = np.random.default_rng(SEED)
    times = np.linspace(0.0, 1.0, 5)
    x0 = rng.uniform(-1.0, 1.0, (N_PATHS, 1, 2))
    arrays = {
        name: np.concatenate([x0, rng.normal(0.0, 0.01, (N_PATHS, times.size - 1, 2))], axis=1)
        for name in ("expert_nominal", "learned_nominal")
    }
    arrays["t"] = times
    data = data_mod._checked(arrays, "stub", "npz", None)
    with pytest.raises(_Stop):
        data_mod.validate_data(
            _stub(claims), data, n_state=2, certified_horizon=1.0, accept_unfingerprinted=True
        )

    expected = {k: getattr(claims, k) for k in CLAIMED}
    assert seen == [expected, expected]
