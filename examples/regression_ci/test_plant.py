"""The worked example's CI test (README "Regression tests against your own gaps").

Run from this folder: ``pytest test_plant.py --drip-cert-update`` records the certificate
snapshot (``drip_cert_baselines/``; commit it in your project), ``pytest test_plant.py`` then
fails when a change of the model, the policy or the data makes the certificate regress.
"""

from pathlib import Path

from drip_cert.testing import assert_certified, assert_gaps_within

HERE = Path(__file__).parent
SPEC = HERE / "plant.toml"


def test_plant_is_certified():
    assert_certified(SPEC)


def test_recorded_gaps_within_the_bounds():
    # gaps.npz carries the fingerprint record_gaps.py writes: after a change of the policy or
    # of the L1-DRAC design the old data are refused (re-record them with record_gaps.py)
    assert_gaps_within(SPEC, HERE / "gaps.npz")


def test_certificate_did_not_regress(drip_cert_baseline):
    drip_cert_baseline.check(SPEC)
