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
