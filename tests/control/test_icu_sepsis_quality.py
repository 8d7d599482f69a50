"""icu-sepsis and icu-sepsis-terminate end to end: a log of clinician episodes (10,000 for
icu-sepsis, the issue's size; 1,000 for the variant) written as a user's plain file (an NPZ with the D4RL keys, no trace of the task:
tests/plain_log.py) and ingested under another name, ``aoc train`` and ``aoc index`` with no
flags, the controller with the settings saved with the model (decided from the log's evidence),
and the exact value of its decisions (every live state decided once: a state policy, valued by
one linear solve over the package's tables).

Guards decision quality: AOC must beat the clinicians who wrote the log by the task's
:data:`THRESHOLD`, with every decision backed by at most d_b + 1 named rows of named patients.
Sizes: docs/results/icu-sepsis.md (the bench at 1k, 10k and 50k episodes).
"""

import numpy as np
import pytest

from aoc_cli.envs import collect, icu_sepsis
from aoc_cli.baselines.sepsis_policies import LIVE, state_policy
from aoc_cli.control import open_session
from aoc_cli.store import Store

#: The log's size per task.
EPISODES = {"icu-sepsis": 10_000, "icu-sepsis-terminate": 1000}
#: Its fixture takes ~3 minutes at 10k episodes: first in the suite (tests/conftest.py).
pytestmark = pytest.mark.long_setup
#: The exact survival AOC's decisions must reach, per task.
#: icu-sepsis at 10k episodes (clinicians 0.7818, random 0.7801, their modal dose 0.7868;
#: Pi_b-SPIBB told the state 0.8032): measured 0.8150 with the settings the log's evidence
#: decides (2026-11-29; 0.7946 at 1k, 0.8413 at 50k), and 0.8150 / 0.8150 / 0.8138 / 0.8133
#: with two other training seeds and two other seeds of the FQE that computes the row values
#: (a perturbation far larger than another CPU's rounding; docs/results/icu-sepsis.md).
#: icu-sepsis-terminate (a dose outside the clinicians' admissible set is fatal; the clinicians'
#: estimated policy 0.4158, which puts ~16% of its mass there; their modal dose 0.7868):
#: measured 0.657 with the settings the log decides (penalty 2.857 measured on the log; rule
#: 2's controller kept, FQE diverged on the held-out episodes), fatal doses in 11.4% of the
#: live states (0.632 and 12.6% with the former task presets); the paper's controller (epsilon 0.5, no cap, no support rule) on the same model 0.384, fatal
#: doses in 25.4% (docs/results/icu-sepsis.md).
THRESHOLD = {"icu-sepsis": 0.81, "icu-sepsis-terminate": 0.60}
STRATEGY = {"icu-sepsis": "mean", "icu-sepsis-terminate": "terminate"}


@pytest.fixture(scope="module", params=sorted(THRESHOLD))
def decided(request, tmp_path_factory):
    from tests.conftest import run_aoc

    task = request.param
    from tests.plain_log import ingest_plain

    root = tmp_path_factory.mktemp("sepsis") / "store"
    env = ingest_plain(collect(task, episodes=EPISODES[task], seed=0)[0], root, "log")
    for args in (("train", "log", "--threads", "1"), ("index", "log")):
        code, _out, err = run_aoc(*args, "--format", "json", env=env)
        assert code == 0, (args, err)
    corpus = Store(root).corpus("log")
    assert "task" not in str(corpus.manifest["sources"])
    session = open_session(corpus, "default")  # the settings saved with the model
    decisions = []

    def decide(observation, history):
        d = session.controller.decide(observation, history)
        decisions.append(d)
        return d

    tables = icu_sepsis.tables(STRATEGY[task])
    assert session.history_length == 0, "the observations recur (a finite state): aoc train " \
        "decides history length 0, so AOC's policy is a state policy"
    policy = state_policy(decide, tables)
    return task, corpus, session, tables, policy, decisions


def test_aoc_beats_the_clinicians_exactly(decided):
    task, _corpus, _session, tables, policy, _decisions = decided
    value = tables.mdp.value(policy)
    clinicians = tables.mdp.value(tables.clinicians)
    assert value >= THRESHOLD[task] > clinicians, (task, value, clinicians)


@pytest.mark.parametrize("decided", ["icu-sepsis-terminate"], indirect=True)
def test_fatal_doses_stay_rare_where_the_variant_makes_them_fatal(decided):
    # rule 2's residual cap keeps the candidates the corpus holds, the support penalty those
    # many patients took: 11.4% of the live states get an inadmissible dose at 1k episodes, the
    # paper's controller 25.4% (the log's clinicians put ~16% of their mass there)
    _task, _corpus, _session, tables, policy, _decisions = decided
    live = np.arange(LIVE)
    assert np.mean(~tables.admissible[live, np.asarray(policy)[live]]) < 0.2


def test_every_decision_is_backed_by_at_most_d_b_plus_one_rows_of_the_log(decided):
    _task, corpus, session, _tables, _policy, decisions = decided
    assert len(decisions) == LIVE
    starts = corpus.episode_starts
    limit = session.model.d_b + 1
    for d in decisions:
        rows = np.asarray(d.support_rows)
        assert 1 <= len(rows) <= limit and np.all((rows >= 0) & (rows < corpus.n_rows))
        episodes = np.searchsorted(starts, rows, side="right") - 1
        assert np.all((episodes >= 0) & (episodes < corpus.n_episodes))
