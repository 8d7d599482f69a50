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
