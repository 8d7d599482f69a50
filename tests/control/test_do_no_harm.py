"""Rule 7, do no harm, on noisy continuous features (a small cohort of the icu-cohort test
bed, aoc_cli/envs/icu_cohort.py): the batched decisions of a vectorised rollout are the
controller's one-step decisions, with histories; the clinicians' likely action is kept where
no bound beats it, and the decision's record says so."""

import numpy as np
import pytest

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli import open_session
from aoc_cli.control.batch import BatchPolicy
from aoc_cli.control.episodes import HistoryBuffer
from aoc_cli.control.records import decision_record
from aoc_cli.index import build_index
from aoc_cli.envs import collect
from aoc_cli.store import Store
from aoc_cli.index.search.neighbourhood import SETS, Neighbourhood


@pytest.fixture(scope="module")
def cohort(tmp_path_factory):
    store = Store(tmp_path_factory.mktemp("cohort"))
    data, _ = collect("icu-cohort", episodes=300, seed=0)
    corpus = store.write("c", data)
    train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=4, patience=2,
                                     history_length=2), "default")
    build_index(corpus)
    return store


def test_the_batch_policy_decides_as_the_controller_does_step_by_step(cohort):
    session = open_session("c", store=cohort)
    ctl = session.controller
    assert ctl.do_no_harm                      # value mode, discrete, no support penalty
    assert ctl.neighbourhood.masked is not None   # the log's gaps: the measured cells' distance
    data = cohort.corpus("c")
    measured = ~data.imputed_mask
    starts = np.asarray(data.episode_starts)
    episodes = [0, 3, 7]
    length = min(int(starts[e + 1] - starts[e]) for e in episodes)
    obs = np.asarray(data.observations)
    policy = BatchPolicy(ctl)
    policy.reset(len(episodes))
    buffers = [HistoryBuffer(2, data.observation_dim, 1, True) for _ in episodes]
    alive = np.arange(len(episodes))
    for t in range(length):
        rows = [starts[e] + t for e in episodes]
        step = obs[rows]
        batch = policy(step, alive, measured[rows])
        # what the step read: rule 7's likely dose over the step's measured cells
        assert np.array_equal(policy.last["likely"], ctl.neighbourhood.at(
            np.asarray(step, np.float32), measured[rows]).likely)   # as the batch reads it
        for j, buf in enumerate(buffers):
            one = ctl.decide(step[j], buf.history(), measured=measured[rows[j]])
            if int(one.action) != int(batch[j]):     # only where two paths' rounding ties
                v = one.candidate_values
                assert abs(v[int(one.action)] - v[int(batch[j])]) < 1e-6, (t, j)
            buf.push(step[j], int(one.action), 0.0)


def test_kept_decisions_are_the_likely_action_and_their_record_says_so(cohort):
    session = open_session("c", store=cohort)
    ctl = session.controller
    data = cohort.corpus("c")
    obs = np.asarray(data.observations)[:200]
    near = ctl.neighbourhood.at(obs)
    kept_any = moved_any = False
    for i in range(0, 200, 5):
        d = ctl.decide(obs[i], HistoryBuffer(2, data.observation_dim, 1, True).history())
        assert d.kept == (int(d.action) == int(near.likely[i]))
        if d.kept:
            kept_any = True
            rec = decision_record(d, data, session.index)
            assert rec["rule"] == "kept the clinicians' dose: no better-supported alternative"
        else:
            moved_any = True
            bounds = ctl.neighbourhood.bounds(near)[i]
            assert bounds[int(d.action)] > bounds[int(near.likely[i])]
            assert bounds[int(d.action)] == bounds.max()
    assert kept_any and moved_any            # both branches checked above
    off = open_session("c", store=cohort, controller={"do_no_harm": "off"}).controller
    assert not off.do_no_harm
    d = off.decide(obs[0], HistoryBuffer(2, data.observation_dim, 1, True).history())
    assert d.kept is None and int(d.action) == int(np.argmax(
        np.where(d.passed, d.candidate_values, -np.inf)))


def test_the_contrast_of_a_rule_7_decision_reads_the_bounds(cohort):
    from aoc_cli.explanation.contrast import contrast_record

    session = open_session("c", store=cohort)
    ctl = session.controller
    data = cohort.corpus("c")
    obs = np.asarray(data.observations)[10]
    history = HistoryBuffer(2, data.observation_dim, 1, True).history()
    d = ctl.decide(obs, history)
    rec = contrast_record(ctl, obs, history, d, data, session.index)
    why = rec["why"]
    bounds = ctl.neighbourhood.bounds(ctl.neighbourhood.at(obs[None]))[0]
    assert why["reason"] in ("lower bound", "no nearby stay received it")
    assert why["chosen_bound"] == bounds[d.chosen]
    if why["reason"] == "lower bound":
        assert why["bound"] == bounds[rec["candidate"]] <= bounds[d.chosen]
    else:
        assert not np.isfinite(bounds[rec["candidate"]])


def test_a_rollout_reads_the_cells_the_environment_held_and_its_audit_replays_them(
        cohort, tmp_path):
    """``aoc rollout --env icu-cohort``: each decision reads the environment's measured cells
    (``info["measured"]``), the audit log keeps them, and a replay decides the same; the same
    step read as fully measured finds other rows."""
    from aoc_cli.control import rollout
    from aoc_cli.control.audit import read_audit_step
    from aoc_cli.envs import make_env
    from aoc_cli.explanation.decisions import replay_decision

    session = open_session("c", store=cohort)
    path = tmp_path / "a.h5"
    results, _ = rollout(session, make_env("icu-cohort"), 3, seed=2, audit=str(path))
    held = [(e, t) for e, res in enumerate(results) for t, m in enumerate(res.measured)
            if not m.all()]
    assert held and all(len(r.measured) == len(r.decisions) for r in results)
    differs = False
    for e, t in held[:6]:
        step = read_audit_step(path, e, t)
        assert (step["measured"] == results[e].measured[t]).all()
        again = replay_decision(session, step)
        assert int(again.action) == int(step["action"])
        ctl = session.controller
        rows = ctl.neighbourhood.at(step["observation"][None], step["measured"][None]).rows
        every = ctl.neighbourhood.at(step["observation"][None]).rows
        differs |= set(rows[0].tolist()) != set(every[0].tolist())
    assert differs                      # the held cells change which rows are nearest


def test_a_model_with_rule_7_values_over_every_cell_is_refused_on_a_log_with_gaps(cohort):
    """Rule 7's values record the distance their neighbourhoods were found by; a model whose
    values were found over every cell (trained before the filled cells were left out) holds
    values over other sets than the controller reads on a log with gaps: it says to retrain."""
    from aoc_cli.belief import load_model
    from aoc_cli.errors import AocError

    corpus = cohort.corpus("c")
    train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=2, patience=1,
                                     value="neighbours", history_length=0), "hood")
    hood = load_model(corpus, "hood")
    assert hood.neighbourhood_values is not None
    made = hood.meta["neighbourhood"]
    assert (made["distance"], made["sets"]) == ("measured cells", SETS)
    assert set(made) == {"distance", "sets", "scale", "centre", "radius", "set_rows"}
    assert 30 <= made["set_rows"]["least"] <= made["set_rows"]["median"] \
        <= made["set_rows"]["most"] <= 1000
    ctl = open_session("c", store=cohort).controller
    ctl.model.neighbourhood_values = hood.neighbourhood_values     # values, no record of how
    with pytest.raises(AocError, match=r"over every cell.*retrain it \(train\('c', "
                                       r"overwrite=True\)\)"):
        ctl.neighbourhood
    # values over the 100 nearest raw rows (before the denoised sets): refused too
    ctl.model.meta["neighbourhood"] = {"distance": "measured cells"}
    with pytest.raises(AocError, match=r"100 nearest rows.*retrain it"):
        ctl.neighbourhood
    ctl.model.meta["neighbourhood"] = hood.meta["neighbourhood"]
    ctl.model.neighbourhood_space = hood.neighbourhood_space
    assert ctl.neighbourhood.masked is not None
    # the saved space rebuilds the sets a fresh build finds, without denoising the log
    obs = np.asarray(corpus.observations)
    space = hood.neighbourhood_space
    assert space["denoised"].shape == obs.shape and space["denoised"].dtype == np.float32
    fresh = Neighbourhood(obs, corpus.actions, np.zeros(len(obs), np.int64),
                          corpus.n_actions, measured=~corpus.imputed_mask)
    assert ctl.neighbourhood.radius == pytest.approx(fresh.radius, rel=1e-12)
    step = obs[::37]
    a, b = ctl.neighbourhood.sets(step), fresh.sets(step)
    assert [a[i].tolist() for i in range(len(a))] == [b[i].tolist() for i in range(len(b))]
