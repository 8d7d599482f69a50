"""FQE's default steps (aoc_cli.ope.fqe.default_steps) follow the log's horizon: FQE moves
a value one step back per target sync, so on a log of long episodes 30 passes over the data
(the default before) stop far short of the fitted fixed point, and the default, which adds
target syncs per step of the episodes' 99th-percentile length, reaches it."""

import numpy as np

from aoc_cli.ope.fqe import (
    MAX_STEPS,
    SYNCS_PER_STEP,
    TARGET_UPDATE,
    default_steps,
    fqe_policies,
    horizon,
)
from aoc_cli.threads import one_thread
from tests.ope.mdps import SmallMDP
from tests.ope.test_ope_fqe_bootstrap import tabular_estimate


def test_default_steps_add_target_syncs_per_step_of_the_horizon():
    starts = np.r_[0, np.cumsum(np.r_[np.full(90, 5), np.full(10, 40)])]   # 100 episodes
    assert horizon(starts) == 40                                    # their 99th percentile
    # 850 rows: 30 passes are 99 steps, under the floor; the horizon asks for more
    want = int(np.ceil(SYNCS_PER_STEP * horizon(starts))) * TARGET_UPDATE
    assert default_steps(int(starts[-1]), starts) == max(1500, min(want, MAX_STEPS))
    assert default_steps(int(starts[-1])) == 1500                  # rows alone: the floor
    # syncs, not steps, are what the horizon asks for: a fit syncing every 300 steps needs 3x
    assert default_steps(int(starts[-1]), starts, target_update=300) == min(3 * want, MAX_STEPS)
    # a discount shortens the horizon: gamma 0.5 falls to 1% within 7 steps
    assert horizon(starts, gamma=0.5) == 7
    assert default_steps(10**7, starts) == MAX_STEPS


def test_fqe_with_the_default_steps_reaches_the_fixed_point_of_long_episodes():
    mdp = SmallMDP.random(n_states=5, n_actions=3, seed=1, end=0.12)
    rng = np.random.default_rng(1)
    s, a = mdp.P.shape[:2]
    greedy = np.eye(a)[rng.integers(0, a, size=s)]
    pi_b = 0.5 * greedy + 0.5 * rng.dirichlet(np.full(a, 2.0), size=s)
    data = mdp.sample(pi_b, 300, seed=11)
    fixed = tabular_estimate(mdp, data, greedy, np.ones(300))     # what a converged FQE gives
    obs = np.eye(s)[data["state"]]                                  # one-hot states
    args = (obs, data["action"], data["reward"], data["starts"], [greedy[data["state"]]])
    steps = default_steps(len(obs), data["starts"])
    assert steps > 1500 and horizon(data["starts"]) > 20
    with one_thread():
        short = fqe_policies(*args, steps=1500, refits=0)[0]       # 30 passes: the floor
        full = fqe_policies(*args, refits=0)[0]
    assert full["steps"] == steps
    assert abs(full["estimate"] - fixed) < 0.03
    assert short["estimate"] < fixed - 0.05                         # under-converged: low
