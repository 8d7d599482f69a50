"""Fitted Q evaluations trained as one batched ensemble in plain torch (aoc_cli.ope.ensemble):
a member started from d3rlpy's DiscreteFQE network and fed the same mini-batches trains as
d3rlpy's own update does (d3rlpy 2.8, the reference, only here), fresh or warm-started, on its
own policy and resampled rows, without touching the other members."""

import contextlib
import io

import numpy as np
import pytest

from aoc_cli.ope.ensemble import FQEEnsemble
from aoc_cli.ope.fqe import FQEFit, cumulative
from aoc_cli.threads import one_thread
from tests.ope.mdps import noisy_log

#: float32 training replayed by the same kernels in another arrangement (other members
#: beside it, a table of the target's values): a few hundred steps agree to about 1e-6 of Q
#: values of order 1.
TOL = 2e-5
#: against d3rlpy's modules (its loss and torch's per-tensor Adam: other roundings): they agree
#: to ~2e-7 until a ReLU whose input lies within rounding of 0 falls on the other side in one,
#: which changes that row's gradient at that unit; measured 8e-4 of Q values of order 0.5
#: 100 steps after such a flip (its first in 320 steps of a member on these logs).
D3RLPY_TOL = 2e-3


@pytest.fixture(scope="module")
def log():
    obs, data, pi_b, rng = noisy_log(seed=1, end=0.35, episodes=200, sample_seed=2)
    s, a = pi_b.shape
    policies = [pi_b, np.eye(a)[rng.integers(0, a, size=s)], rng.dirichlet(np.ones(a), size=s)]
    return obs, data, [p[data["state"]] for p in policies]


def make(log, policy=0, seed=0):
    obs, data, policies = log
    return FQEFit(obs, data["action"], data["reward"], data["starts"], policies[policy],
                  seed=seed)


class D3rlpyFQE:
    """d3rlpy's DiscreteFQE on ``fit``'s log at FQE's settings, updated by its own
    ``update`` on the mini-batches and next actions it is given."""

    def __init__(self, fit, cosine_steps=None):
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(
                io.StringIO()):
            d3rlpy = pytest.importorskip("d3rlpy", reason="the bench extra (d3rlpy)")
        from d3rlpy.models.encoders import VectorEncoderFactory
        from d3rlpy.ope import DiscreteFQE, FQEConfig
        from d3rlpy.optimizers import AdamFactory
        from d3rlpy.optimizers.lr_schedulers import CosineAnnealingLRFactory

        d3rlpy.seed(fit.seed)
        self.fit, self.actions, self.impl = fit, None, self
        optim = AdamFactory() if cosine_steps is None else AdamFactory(
            lr_scheduler_factory=CosineAnnealingLRFactory(T_max=int(cosine_steps)))
        self.fqe = DiscreteFQE(algo=self, config=FQEConfig(
            batch_size=fit.batch, gamma=fit.gamma, learning_rate=fit.learning_rate,
            target_update_interval=fit.interval, optim_factory=optim,
            encoder_factory=VectorEncoderFactory(hidden_units=list(fit.hidden))), device=False)
        self.fqe.create_impl((fit.x.shape[1],), fit.n_actions)

    def predict_best_action(self, x):           # the 'algorithm' FQE evaluates
        import torch

        return torch.as_tensor(self.actions, dtype=torch.long)

    def weights(self) -> list:
        """Its network's weights in torch's layout, [W_1, b_1, ...], read from the file of
        d3rlpy's public ``save_model`` (its modules' state dicts, ``q_funcs`` the Q network)."""
        import tempfile

        import torch

        with tempfile.TemporaryDirectory() as tmp:
            path = f"{tmp}/fqe.pt"
            self.fqe.save_model(path)
            states = torch.load(path, weights_only=True)
        return [t.detach().clone() for t in states["q_funcs"].values()]

    def update(self, rows, next_actions) -> None:
        from d3rlpy.dataset import TransitionMiniBatch

        fit, B = self.fit, len(rows)
        self.actions = next_actions
        self.fqe.update(TransitionMiniBatch(
            observations=fit.x[rows], actions=fit.act[rows, None].astype(np.float32),
            rewards=fit.rew[rows, None], next_observations=fit.x[fit.nxt[rows]],
            next_actions=np.zeros((B, 1), np.float32),
            terminals=fit.last[rows, None].astype(np.float32),
            intervals=np.ones((B, 1), np.float32), transitions=[]))

    def q(self) -> np.ndarray:
        n, x = self.fit.n_actions, self.fit.x
        return self.fqe.predict_value(np.repeat(x, n, 0), np.tile(np.arange(n), len(x))
                                      ).reshape(len(x), n)


def recorded(draw, refs, of=None):
    """draw() that also updates each d3rlpy reference on its member's rows and next actions
    (reference j: member ``of[j]``; None: member j)."""
    def both():
        rows, acts = draw()
        for j, ref in enumerate(refs):
            m = j if of is None else of[j]
            ref.update(rows[m], acts[m])
        return rows, acts
    return both


def test_a_fresh_member_trains_as_d3rlpys_own_update(log):
    from aoc_cli.ope.ensemble import sampler

    with one_thread():
        fit = make(log)
        ref = D3rlpyFQE(fit)
        ens = FQEEnsemble(fit, 1, ref.weights())
        draw = sampler(fit, fit.cum[None], np.zeros(1, np.int64), [None], fit.rng, 1)
        ens.train(230, None, None, None, None, draw=recorded(draw, [ref]))
    q_ref = ref.q()
    assert np.abs(q_ref).max() > 0.1              # it learned something
    assert np.abs(ens.q()[0] - q_ref).max() < D3RLPY_TOL


def test_the_cosine_schedule_is_d3rlpys_cosine_annealing(log):
    """schedule="cosine" over n steps: d3rlpy's FQE with Adam under CosineAnnealingLR(T_max n)."""
    from aoc_cli.ope.ensemble import sampler

    with one_thread():
        fit = make(log)
        ref, plain = D3rlpyFQE(fit, cosine_steps=230), D3rlpyFQE(fit)
        ens = FQEEnsemble(fit, 1, ref.weights())
        draw = sampler(fit, fit.cum[None], np.zeros(1, np.int64), [None], fit.rng, 1)
        ens.train(230, None, None, None, None, draw=recorded(draw, [ref, plain], [0, 0]),
                  schedule="cosine")
    assert np.abs(ens.q()[0] - ref.q()).max() < D3RLPY_TOL
    assert np.abs(plain.q() - ref.q()).max() > 5 * D3RLPY_TOL   # the schedule mattered


def test_warm_started_members_each_match_their_own_d3rlpy_fit(log):
    """Three members warm-started from one trained member (weights, target, Adam's moments,
    step count), each on another policy and another multiset of rows, against three d3rlpy
    fits doing the same one at a time: no member leaks into another."""
    from aoc_cli.ope.ensemble import sampler

    with one_thread():
        fit = make(log)
        refs = [D3rlpyFQE(fit) for _ in range(3)]
        ens = FQEEnsemble(fit, 1, refs[0].weights())
        first = sampler(fit, fit.cum[None], np.zeros(1, np.int64), [None], fit.rng, 1)
        # the same first 150 mini-batches for each reference
        ens.train(150, None, None, None, None, draw=recorded(first, refs, [0, 0, 0]))
        cums = np.stack([cumulative(p) for p in log[2]])
        pools = [None, np.arange(0, fit.n_rows, 3), np.repeat(np.arange(40), 2)]
        three = ens.repeat(3)
        assert list(three.counts) == [150] * 3
        draw = sampler(fit, cums, np.arange(3), pools, np.random.default_rng(10), 3)
        three.train(170, None, None, None, None, draw=recorded(draw, refs))
    got = three.q()
    for m, ref in enumerate(refs):
        assert np.abs(got[m] - ref.q()).max() < D3RLPY_TOL
    assert np.abs(got[0] - got[1]).max() > 10 * D3RLPY_TOL     # the members did differ


def test_fqe_starts_from_torchs_linear_initialisation_and_leaves_the_generator(log):
    import torch

    fit = make(log, seed=4)
    state = torch.get_rng_state()
    w = fit.initial()
    assert torch.equal(torch.get_rng_state(), state)
    torch.manual_seed(4)
    first = torch.nn.Linear(fit.x.shape[1], fit.hidden[0])
    assert torch.equal(w[0], first.weight.detach()) and torch.equal(w[1], first.bias.detach())
    assert [tuple(t.shape) for t in w[-2:]] == [(fit.n_actions, fit.hidden[-1]),
                                               (fit.n_actions,)]


def test_repeat_warm_starts_copies_that_train_on_as_the_original(log):
    with one_thread():
        fit = make(log)
        ens = FQEEnsemble(fit, 1)
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
            ens = FQEEnsemble(fit, 2)
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
        alone = FQEEnsemble(fit, 1)
        alone.train(150, None, None, None, None, draw=own())
        first = FQEEnsemble(fit, 1)
        first.train(150, None, None, None, None, draw=shared())
        both = FQEEnsemble(fit, 2)
        both.train(150, None, None, None, None, draw=joined(shared(), own()))
    assert np.abs(both.q()[1] - alone.q()[0]).max() < TOL
    assert np.abs(both.q()[0] - first.q()[0]).max() < TOL
    assert np.abs(both.q()[0] - both.q()[1]).max() > 10 * TOL


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
