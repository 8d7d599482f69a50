"""An FQE ensemble trained in parts over forked processes (aoc_cli.ope.parts): every
member trains as in one process (the same mini-batches, the same floats to a few ulp), the
shared generator ends where one process leaves it, and a child that dies is made up for.
(Where a process cannot fork, every number of parts is one: the same assertions hold.)"""

import numpy as np
import pytest

from aoc_cli.ope import parts as ope_parts
from aoc_cli.ope.ensemble import FQEEnsemble, sampler
from aoc_cli.ope.fqe import FQEFit, cumulative, fqe_policies
from aoc_cli.threads import one_thread
from tests.ope.mdps import noisy_log

#: the same member trained in another process: the same kernels on the same inputs; a few
#: float32 ulp of Q values of order 1 allowed for a library that picks kernels by shape
ULP = 1e-6


@pytest.fixture(scope="module")
def log():
    obs, data, pi_b, rng = noisy_log(seed=3, end=0.3, episodes=150, sample_seed=4)
    s, a = pi_b.shape
    policies = [np.eye(a)[rng.integers(0, a, size=s)][data["state"]] for _ in range(3)]
    return obs, data, policies


def ensemble(log, M):
    obs, data, policies = log
    fit = FQEFit(obs, data["action"], data["reward"], data["starts"], policies[0])
    cums = np.stack([cumulative(p) for p in policies])
    pools = [None if m % 2 else np.arange(0, fit.n_rows, 3) for m in range(M)]
    make_draw = lambda keep, rng: sampler(fit, cums, np.arange(M) % 3, pools, rng, M, keep=keep)
    return FQEEnsemble(fit, M), make_draw


def trained(log, M, parts, steps=140):
    with one_thread():
        ens, make_draw = ensemble(log, M)
        rng = np.random.default_rng(11)
        ope_parts.train_parts(ens, steps, make_draw, rng, parts, schedule="cosine")
    return ens, rng


@pytest.mark.parametrize("parts", [2, 3])
def test_members_trained_in_parts_are_the_members_trained_together(log, parts):
    one, rng_one = trained(log, 5, 1)
    split, rng_split = trained(log, 5, parts)
    q1, q2 = one.q(), split.q()
    assert np.abs(q1).max() > 0.1                     # it learned something
    assert np.abs(q1[0] - q1[1]).max() > 100 * ULP    # and the members differ
    np.testing.assert_allclose(q2, q1, rtol=0, atol=ULP)
    assert list(split.counts) == [140] * 5
    for mine, theirs in zip(split.params, one.params):   # Adam's moments came back too
        s1, s2 = one.optim.state[theirs], split.optim.state[mine]
        assert float(s1["step"]) == float(s2["step"]) == 140
        np.testing.assert_allclose(s2["exp_avg_sq"].numpy(), s1["exp_avg_sq"].numpy(),
                                   rtol=1e-5, atol=1e-12)
    assert rng_split.random() == rng_one.random()     # the shared generator ends as one's


def test_a_child_that_dies_has_its_part_trained_here(log, monkeypatch):
    monkeypatch.setattr(ope_parts, "_child", lambda *args: ope_parts.os._exit(3))
    one, _ = trained(log, 4, 1)
    split, _ = trained(log, 4, 2)
    np.testing.assert_allclose(split.q(), one.q(), rtol=0, atol=ULP)


def test_fqe_policies_gives_the_same_estimates_in_any_number_of_parts(log):
    obs, data, policies = log
    args = (obs, data["action"], data["reward"], data["starts"], policies)
    kw = dict(steps=300, refits=3, refit_step_count=100, behaviour=True)
    with one_thread():
        one = fqe_policies(*args, parts=1, **kw)
        two = fqe_policies(*args, parts=2, **kw)
    assert len(one) == len(two) == 4                  # three policies and the behaviour
    for a, b in zip(one, two):
        assert abs(a["estimate"] - b["estimate"]) < ULP
        np.testing.assert_allclose(b["q"], a["q"], rtol=0, atol=ULP)
    for a, b in zip(one[:3], two[:3]):
        np.testing.assert_allclose(b["replicates"], a["replicates"], rtol=0, atol=ULP)


def test_a_child_that_hangs_is_ended_and_its_part_trained_here(log, monkeypatch):
    """A child that never answers does not hang the caller: after the grace period it is
    ended and its part trained here, to the same floats."""
    import time

    monkeypatch.setattr(ope_parts, "_child", lambda *args: time.sleep(3600))
    monkeypatch.setattr(ope_parts, "GRACE_SECONDS", 1.0)
    monkeypatch.setattr(ope_parts, "PATIENCE", 0.0)
    one, _ = trained(log, 4, 1)
    began = time.monotonic()
    split, _ = trained(log, 4, 2)
    assert time.monotonic() - began < 60
    np.testing.assert_allclose(split.q(), one.q(), rtol=0, atol=ULP)
