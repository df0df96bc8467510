"""The one pipeline and the certify API: one seed, one set of demonstrations, Spec or System.

Small runs (a 2-state system, 40 training steps): what is tested is the plumbing of data and
seeds, which does not depend on how well the policy is trained.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drip_cert.bounds.certificate import certify
from drip_cert.learn.imitation import demonstration_set
from drip_cert.spec import load_spec
from drip_cert.spec.load import Spec
from drip_cert.workflows import run_pipeline
from tests.helpers import example_spec

SPEC = example_spec("unmatched_2d")
STEPS = 40  #: training steps: enough to produce a policy; its quality is not under test
SEED = 3  #: not the spec's [tasil] seed (0), so a seed that is not passed on would show


#: work budget of the learned loop's branch and bound: what is tested is the plumbing, and a
#: small count keeps each certify to seconds (the default, 4000 boxes, costs a minute per loop)
MAX_BOXES = 100


def _small(spec: Spec) -> Spec:
    """The spec with a small [tasil] (few trajectories, a small network) and a small work budget,
    without [l1drac] (faster)."""
    st = spec.settings
    tasil = dataclasses.replace(
        st.tasil, steps=STEPS, trajectories=8, heldout=16, samples=50, hidden=(8, 8)
    )
    contraction = dataclasses.replace(st.contraction, max_boxes=MAX_BOXES)
    present = (st.present - {"l1drac"}) | {"tasil", "contraction"}
    return spec.with_settings(
        dataclasses.replace(st, tasil=tasil, contraction=contraction, present=present)
    )


@pytest.fixture(scope="module")
def run():
    return run_pipeline(_small(load_spec(SPEC)), seed=SEED, certify=True)


def test_the_pipeline_certifies_on_the_demonstrations_it_trained_on(run):
    """The TaSIL section counts exactly the pipeline's trajectories, drawn from the one seed."""
    demos = run.demonstrations
    assert demos is not None and demos.seed == SEED
    tp = run.trained["tasil"]
    assert tp.demonstrations is demos  # training saw this very set
    tasil = run.certificate.tasil
    assert tasil is not None
    assert tasil.n == demos.train.states.shape[0] == 8
    assert tasil.n_val == demos.heldout.states.shape[0] == 16


def test_certify_redraws_the_same_demonstrations_from_the_same_seed(run):
    """Two routes to one number: certify with the pipeline's demonstrations, and certify of a spec
    whose [tasil] seed is the pipeline's seed (demonstrations redrawn), give the same TaSIL bound;
    a different seed gives different data, hence (generically) a different h0."""
    spec = run.spec  # carries the trained policy
    st = spec.settings

    def seeded(seed: int) -> Spec:
        return spec.with_settings(
            dataclasses.replace(st, tasil=dataclasses.replace(st.tasil, seed=seed))
        )

    again = certify(seeded(SEED))
    assert again.tasil.h0 == run.certificate.tasil.h0
    assert again.tasil.rho == run.certificate.tasil.rho
    assert certify(seeded(SEED + 1)).tasil.h0 != run.certificate.tasil.h0


def test_certify_accepts_a_bare_system_and_a_policy(run):
    """certify(System) uses default settings; policy= attaches an MLP as pi_IL."""
    base = load_spec(SPEC).system
    c_sys = certify(base)
    c_spec = certify(Spec(None, base))
    assert c_sys.contraction_expert.euclidean.rate == c_spec.contraction_expert.euclidean.rate
    assert c_sys.tasil is None  # no learned policy: no TaSIL part
    assert c_sys.to_dict()["parts"]["tasil"]["verdict"] == "not_applicable"
    mlp = run.trained["tasil"].mlp
    demos = run.demonstrations
    budget = {"contraction": {"max_boxes": MAX_BOXES}}  # the loop's proof is not under test
    c_pol = certify(Spec(None, base, budget), policy=mlp, demonstrations=demos)
    assert c_pol.system.learned is not None
    assert c_pol.tasil is not None and c_pol.tasil.n == demos.train.states.shape[0]


def test_demonstration_set_streams_are_independent_and_reproducible():
    s = load_spec(SPEC).system
    st = dataclasses.replace(load_spec(SPEC).settings.tasil, trajectories=4, heldout=4, seed=SEED)
    a, b = demonstration_set(s, st), demonstration_set(s, st)
    np.testing.assert_array_equal(a.train.states, b.train.states)  # same seed: same draw
    assert not np.array_equal(a.train.x0, a.heldout.x0)  # streams 0 and 1 differ


def test_pipeline_refuses_to_certify_without_a_policy_when_told_not_to_train():
    from drip_cert.errors import SpecError

    with pytest.raises(SpecError, match="no learned policy"):
        run_pipeline(_small(load_spec(SPEC)), train=False)
