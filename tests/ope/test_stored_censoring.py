"""The OPE reads a stored corpus's censoring: ``aoc evaluate --data h`` on a cohort whose stays
were cut short censors them (their last step's outcome unknown), as it does for in-memory
arrays; read as deaths they bias every estimate down by the censored share (3% of the stays
of the cohort test bed: its clinicians' 0.78 read as 0.76)."""

import numpy as np

from aoc_cli.envs import collect
from aoc_cli.ope.evaluate_block import truncated
from aoc_cli.store import Store


def test_a_stored_corpus_and_its_arrays_censor_the_same_stays(tmp_path):
    data, _ = collect("icu-cohort", episodes=400, seed=3)
    last = np.asarray(data.episode_starts)[1:] - 1
    cut = np.asarray(data.truncations, bool)[last] & ~np.asarray(data.terminals, bool)[last]
    assert cut.sum() >= 3                                # the test bed cuts 3% of the stays
    stored = Store(tmp_path).write("c", data)
    assert (truncated(stored) == cut).all()
    assert (truncated(data) == cut).all()


def test_the_behaviours_own_value_counts_a_cut_stay_while_it_was_seen(tmp_path):
    """Kaplan-Meier's mean (PDWIS with every ratio 1), not the mean return that reads a cut
    stay as a death: the check FQE's value of the behaviour must pass compares with it."""
    from aoc_cli.ope import estimators as ope
    from aoc_cli.ope.evaluate_block import OPESettings, off_policy_values

    data, _ = collect("icu-cohort", episodes=400, seed=3)
    stored = Store(tmp_path).write("c", data)
    acts = np.asarray(stored.actions)
    out = off_policy_values(stored, acts, {"aoc": acts},
                            OPESettings(estimators=("pdwis",), n_boot=50))
    cut = truncated(stored)
    assert out["ope"]["truncated_episodes"] == int(cut.sum())
    log = ope.Log(stored.episode_starts, stored.rewards, 1.0, cut)
    km = ope.pdwis(log, np.ones(stored.n_rows))
    got = out["behaviour_value"]["estimate"]
    assert got == np.float64(km) or abs(got - km) < 1e-12
    naive = float(log.returns().mean())
    assert km > naive                       # the cut stays' survivors are not read as deaths


def test_a_difference_from_the_behaviour_reads_its_value_as_kaplan_meiers(tmp_path):
    """The verdict's difference subtracts the behaviour's own value, Kaplan-Meier's under
    censoring, not the mean return: the behaviour itself is then no better than the behaviour
    (by PDWIS, 0 in every replicate), and FQE's difference is each refit's value less
    Kaplan-Meier's over the refit's own resample. (With the mean return the cut stays'
    survivors were read as deaths and every policy shown better by their share: 0.02 on the
    test bed's held-out logs.)"""
    from aoc_cli.ope import estimators as ope
    from aoc_cli.ope.evaluate_block import OPESettings
    from aoc_cli.ope.fqe import student_quantile
    from aoc_cli.ope.value import policy_value

    data, _ = collect("icu-cohort", episodes=800, seed=3)
    starts, acts = np.asarray(data.episode_starts), np.asarray(data.actions, np.int64)
    log = ope.Log(starts, data.rewards, 1.0, truncated(data))
    km = ope.pdwis(log, np.ones(len(acts)))
    assert km > float(log.returns().mean()) + 0.005       # the censored share is material
    probs = np.eye(25)[acts]                # the logged actions, with propensity 1: rho = 1
    counts = np.random.default_rng(0).multinomial(log.n_episodes, np.full(
        log.n_episodes, 1 / log.n_episodes), size=3).astype(np.float64)
    reps = np.array([0.80, 0.82, 0.79])
    fqe = {"q": np.zeros((len(acts), 25)), "replicates": reps, "counts": counts,
           "estimate": 0.80, "low": 0.78, "high": 0.82, "refit_steps": 10, "steps": 100,
           "fit_estimate": 0.80}
    rec = policy_value(log, np.asarray(data.observations), acts, np.ones(len(acts)), probs, 25,
                       OPESettings(estimators=("pdwis", "fqe"), n_boot=50), fqe=fqe)
    gain = rec["improvement"]["pdwis"]
    assert max(abs(gain[k]) for k in ("estimate", "low", "high")) < 1e-12
    diff = rec["improvement"]["fqe"]
    assert abs(diff["estimate"] - (0.80 - km)) < 1e-12
    own = reps - np.array([ope.behaviour_values(log, c[None])[0] for c in counts])
    half = student_quantile(2) * float(np.std(own, ddof=1))
    assert abs(diff["low"] - (0.80 - km - half)) < 1e-12
    assert abs(diff["high"] - (0.80 - km + half)) < 1e-12
    # each resample's value is Kaplan-Meier's over the episodes it drew, repeated as drawn
    c = counts[0].astype(np.int64)
    drawn = np.repeat(np.arange(log.n_episodes), c)
    lengths = np.diff(starts)[drawn]
    rows = np.concatenate([np.arange(starts[e], starts[e + 1]) for e in drawn])
    again = ope.Log(np.r_[0, np.cumsum(lengths)], np.asarray(data.rewards)[rows], 1.0,
                    truncated(data)[drawn])
    assert abs(ope.behaviour_values(log, counts[:1])[0]
               - ope.pdwis(again, np.ones(len(rows)))) < 1e-12
