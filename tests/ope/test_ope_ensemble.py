"""Fitted Q evaluations trained as one batched ensemble (aoc_cli.ope.ensemble): each
member is d3rlpy's DiscreteFQE trained by its own update (``FQEFit.train`` calls
``DiscreteFQE.update``), to float rounding, fresh or warm-started, on its own policy and
resampled rows, without touching the other members."""

import numpy as np
import pytest

from aoc_cli.ope.ensemble import FQEEnsemble
from aoc_cli.ope.fqe import FQEFit, cumulative
from aoc_cli.threads import one_thread
from tests.ope.mdps import noisy_log

pytest.importorskip("d3rlpy", reason="the bench extra (d3rlpy) is not installed")

#: float32 training replayed by another sequence of kernels: a few hundred steps agree to
#: about 1e-6 of Q values of order 1 (measured 3e-6 at worst after 400 steps).
TOL = 2e-5


@pytest.fixture(scope="module")
def log():
    obs, data, pi_b, rng = noisy_log(seed=1, end=0.35, episodes=200, sample_seed=2)
    s, a = pi_b.shape
    policies = [pi_b, np.eye(a)[rng.integers(0, a, size=s)], rng.dirichlet(np.ones(a), size=s)]
    return obs, data, [p[data["state"]] for p in policies]


def make(log, policy=0, seed=0, cosine_steps=None):
    obs, data, policies = log
    return FQEFit(obs, data["action"], data["reward"], data["starts"], policies[policy],
                  seed=seed, cosine_steps=cosine_steps)


def replay(fits, pools):
    """draw() giving each member the rows and next actions ``FQEFit.train`` draws for it."""
    def draw():
        rows, acts = [], []
        for fit, pool in zip(fits, pools):
            B = fit.batch
            idx = fit.rng.integers(0, fit.n_rows, B) if pool is None else \
                pool[fit.rng.integers(0, len(pool), B)]
            acts.append((fit.cum[fit.nxt[idx]] < fit.rng.random((B, 1))).sum(1).clip(
                0, fit.n_actions - 1))
            rows.append(idx)
        return np.stack(rows), np.stack(acts)
    return draw


def test_a_fresh_member_trains_as_d3rlpys_own_update(log):
    with one_thread():
        ref, twin = make(log), make(log)          # same seed: same initial weights, same draws
        ref.train(230)                            # d3rlpy's DiscreteFQE.update, 230 times
        ens = FQEEnsemble(twin, [twin.snapshot()], [twin.fqe._grad_step])
        ens.train(230, None, None, None, None, draw=replay([twin], [None]))
    q_ref = ref.q()
    assert np.abs(q_ref).max() > 0.1              # it learned something
    assert np.abs(ens.q()[0] - q_ref).max() < TOL


def test_the_cosine_schedule_is_d3rlpys_cosine_annealing(log):
    """schedule="cosine" over n steps: d3rlpy's FQE with Adam under CosineAnnealingLR(T_max n)."""
    with one_thread():
        ref, twin = make(log, cosine_steps=230), make(log)
        ref.train(230)
        ens = FQEEnsemble(twin, [twin.snapshot()], [twin.fqe._grad_step])
        ens.train(230, None, None, None, None, draw=replay([twin], [None]), schedule="cosine")
        plain = make(log)
        plain.train(230)
    assert np.abs(ens.q()[0] - ref.q()).max() < TOL
    assert np.abs(plain.q() - ref.q()).max() > 100 * TOL       # the schedule mattered


def test_warm_started_members_each_match_their_own_d3rlpy_fit(log):
    """Three members from one trained fit (weights, target, Adam's moments, step count), each
    on another policy and another multiset of rows, against three d3rlpy fits doing the same
    one at a time: no member leaks into another."""
    with one_thread():
        base = make(log)
        base.train(150)
        state = base.snapshot()
        count = base.fqe._grad_step
        pools = [None, np.arange(0, base.n_rows, 3), np.repeat(np.arange(40), 2)]
        refs = []
        for m in range(3):
            fit = make(log, policy=m)
            fit.restore(state)
            fit.fqe._grad_step = count
            fit.rng = np.random.default_rng(10 + m)
            refs.append(fit)
        twins = [make(log, policy=m) for m in range(3)]
        for m, t in enumerate(twins):
            t.rng = np.random.default_rng(10 + m)
        ens = FQEEnsemble(base, [state] * 3, [count] * 3)
        ens.train(170, None, None, None, None, draw=replay(twins, pools))
        for fit, pool in zip(refs, pools):
            fit.train(170, pool)
    got = ens.q()
    for m, fit in enumerate(refs):
        assert np.abs(got[m] - fit.q()).max() < TOL
    assert np.abs(got[0] - got[1]).max() > 10 * TOL       # the members did differ


def test_repeat_warm_starts_copies_that_train_on_as_the_original(log):
    with one_thread():
        fit = make(log)
        ens = FQEEnsemble(fit, [fit.snapshot()], [0])
        ens.train(120, cumulative(log[2][0])[None], np.zeros(1, int), [None],
                  np.random.default_rng(0))
        copies = ens.repeat(3)
        assert copies.M == 3 and list(copies.counts) == [120] * 3
        q = copies.q()
        assert all(np.allclose(q[m], ens.q()[0], rtol=1e-6, atol=1e-7) for m in range(3))
        draws = np.random.default_rng(7)
        ens.train(60, cumulative(log[2][0])[None], np.zeros(1, int), [None], draws)
        copies.train(60, None, None, None, None, draw=_first_member_thrice(
            cumulative(log[2][0]), fit, np.random.default_rng(7)))
    assert np.abs(copies.q()[2] - ens.q()[0]).max() < TOL


def _first_member_thrice(cum, fit, rng):
    """The default sampler's draws for one member, given to three."""
    from aoc_cli.ope.ensemble import sampler

    one = sampler(fit, cum[None], np.zeros(1, np.int64), [None], rng, 1)

    def draw():
        rows, acts = one()
        return np.repeat(rows, 3, 0), np.repeat(acts, 3, 0)
    return draw


def test_a_member_state_restored_into_d3rlpy_predicts_the_same_q(log):
    with one_thread():
        fit = make(log)
        ens = FQEEnsemble(fit, [fit.snapshot()] * 2, [0, 0])
        ens.train(80, np.stack([fit.cum, cumulative(log[2][1])]), np.array([0, 1]),
                  [None, np.arange(30)], np.random.default_rng(3))
        other = make(log, seed=5)                 # other initial weights, overwritten
        other.restore(ens.state(1))
        assert other.fqe._grad_step == 80
        # the round trip through d3rlpy's predict_value
        assert np.abs(other.q() - ens.q()[1]).max() < 1e-5
        other.train(20)                           # and d3rlpy trains on from it
        assert np.isfinite(other.q()).all()


def test_thesampler_draws_each_member_from_its_pool_and_policy(log):
    from aoc_cli.ope.ensemble import sampler

    fit = make(log)
    det = cumulative(log[2][1])                   # a deterministic policy
    pools = [np.array([3, 5, 7]), None]
    draw = sampler(fit, np.stack([fit.cum, det]), np.array([1, 0]), pools,
                    np.random.default_rng(0), 2)
    rows, acts = draw()
    assert rows.shape == acts.shape == (2, fit.batch)
    assert set(rows[0]) == {3, 5, 7}              # member 0: only its pool, all of it
    assert len(set(rows[1])) > 20                 # member 1: every row
    # member 0 evaluates the deterministic policy: its action at the next logged step
    assert np.array_equal(acts[0], log[2][1][fit.nxt[rows[0]]].argmax(1))


def test_deterministic_policies_draw_the_next_actions_of_the_general_rule(log, monkeypatch):
    """Where every policy is deterministic the next actions come from each row's action, not
    from the (M, B, n) comparison with the cumulative probabilities: the same draws."""
    from aoc_cli.ope import ensemble as ope_ensemble

    fit = make(log)
    n, rng = fit.n_actions, np.random.default_rng(3)
    cums = np.stack([cumulative(np.eye(n)[rng.integers(0, n, fit.n_rows)]) for _ in range(2)])
    assert ope_ensemble._deterministic(cums) is not None
    assert ope_ensemble._deterministic(np.stack([fit.cum])) is None      # the behaviour's
    args = (fit, cums, np.array([0, 1, 1]), [None, None, np.arange(0, fit.n_rows, 2)])
    fast = ope_ensemble.sampler(*args, np.random.default_rng(5), 3)
    monkeypatch.setattr(ope_ensemble, "_deterministic", lambda _cums: None)
    general = ope_ensemble.sampler(*args, np.random.default_rng(5), 3)
    for _ in range(20):
        (r1, a1), (r2, a2) = fast(), general()
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(a1, a2)
        assert len(np.unique(a1)) > 1


def test_the_target_table_of_repeated_observations_gives_the_per_batch_q(log, monkeypatch):
    """Where observations repeat, the target network's Q comes from a table of the distinct
    observations, refreshed at each sync: the same training as its forward pass per batch."""
    obs, data, policies = log
    rep = np.round(obs[:, :4], 0)                 # few distinct observations (the states)
    cums = np.stack([cumulative(p) for p in policies[:2]])

    def trained(table: bool):
        with one_thread():
            fit = FQEFit(rep, data["action"], data["reward"], data["starts"], policies[0])
            if not table:                         # as a log with too many to tabulate
                monkeypatch.setattr(fit, "distinct", lambda: (np.zeros((10 ** 6, 1)), None))
            ens = FQEEnsemble(fit, [fit.snapshot()] * 2, [0, 0])
            assert (ens._next_table() is not None) == table
            ens.train(250, cums, np.array([0, 1]), [None, None], np.random.default_rng(4))
            return ens.q()

    xu, _of = FQEFit(rep, data["action"], data["reward"], data["starts"],
                     policies[0]).distinct()
    assert len(xu) < 10
    with_table, without = trained(True), trained(False)
    assert np.abs(with_table).max() > 0.1
    assert np.abs(with_table - without).max() < TOL


def test_a_group_drawn_by_its_own_generator_trains_the_same_beside_others(log):
    """joined draws: a member with its own generator gets the same mini-batches, so the same
    training, alone or beside other members (and they the same without it)."""
    from aoc_cli.ope.ensemble import joined, sampler

    with one_thread():
        fit = make(log)
        cums = np.stack([fit.cum, cumulative(log[2][1])])
        own = lambda: sampler(fit, cums[1:], np.zeros(1, np.int64), [None],
                              np.random.default_rng(9), 1)
        shared = lambda: sampler(fit, cums[:1], np.zeros(1, np.int64), [None],
                                 np.random.default_rng(8), 1)
        alone = FQEEnsemble(fit, [fit.snapshot()], [0])
        alone.train(150, None, None, None, None, draw=own())
        first = FQEEnsemble(fit, [fit.snapshot()], [0])
        first.train(150, None, None, None, None, draw=shared())
        both = FQEEnsemble(fit, [fit.snapshot()] * 2, [0, 0])
        both.train(150, None, None, None, None, draw=joined(shared(), own()))
    assert np.abs(both.q()[1] - alone.q()[0]).max() < TOL
    assert np.abs(both.q()[0] - first.q()[0]).max() < TOL
    assert np.abs(both.q()[0] - both.q()[1]).max() > 10 * TOL


def test_the_written_out_backpropagation_is_autograds(log):
    """FQEEnsemble._grads: the gradient of the members' Huber losses as autograd computes it
    through the same forward pass (errors inside and outside Huber's quadratic part)."""
    import torch

    with one_thread():
        fit = make(log)
        ens = FQEEnsemble(fit, [fit.snapshot()] * 3, [0] * 3)
        ens.train(60, np.stack([fit.cum] * 3), np.arange(3), [None] * 3,
                  np.random.default_rng(2))          # members that differ
        rng = np.random.default_rng(4)
        rows = rng.integers(0, fit.n_rows, (3, fit.batch))
        x, act = torch.from_numpy(fit.x[rows]), torch.from_numpy(fit.act[rows])
        y = torch.from_numpy(rng.normal(0.5, 1.5, (3, fit.batch)).astype(np.float32))
        with torch.no_grad():                            # as FQEEnsemble.train calls it
            got = ens._grads(x, act, y)
        q = ens._forward(ens.params, x).gather(2, act[..., None])[..., 0]
        diff = y - q
        assert (diff.abs() > 1).any() and (diff.abs() < 1).any()
        huber = torch.where(diff.detach().abs() < 1.0, 0.5 * diff ** 2, diff.abs() - 0.5)
        want = torch.autograd.grad(huber.mean(1).sum(), ens.params)
    for g, w in zip(got, want):
        assert g.shape == w.shape
        assert float(w.abs().max()) > 0
        np.testing.assert_allclose(g.numpy(), w.numpy(), rtol=1e-5, atol=1e-7)


def test_a_kept_members_draw_is_its_part_of_the_whole_draw(log):
    """sampler(keep=...): the rows and next actions of the kept members, as the whole draw
    gives them, the generator drawn for every member (it ends where the whole draw's does)."""
    from aoc_cli.ope.ensemble import sampler

    fit = make(log)
    cums = np.stack([fit.cum, cumulative(log[2][1])])
    args = (fit, cums, np.array([0, 1, 1, 0]), [None, np.arange(40), None, np.arange(9, 90)])
    whole = sampler(*args, np.random.default_rng(6), 4)
    rng = np.random.default_rng(6)
    part = sampler(*args, rng, 4, keep=np.array([1, 3]))
    for _ in range(5):
        (rows, acts), (kept_rows, kept_acts) = whole(), part()
        np.testing.assert_array_equal(kept_rows, rows[[1, 3]])
        np.testing.assert_array_equal(kept_acts, acts[[1, 3]])
    assert rng.random() == np.random.default_rng(6).random(5 * 4 * fit.batch * 2 + 1)[-1]
