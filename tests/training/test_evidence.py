"""Settings decided from the log's own evidence (aoc_cli.training.evidence), never from a task's
name: the same log collected or written to a plain file gets the same settings; the rules;
flags win, --paper skips; the controller's settings travel with the model."""

import json

import numpy as np
import pytest

from aoc_cli.training import epsilon_rule, evidence
from aoc_cli.training.evidence import Evidence, decide
from aoc_cli.envs import collect
from aoc_cli.store import Store
from tests.plain_log import write_plain_npz

QUICK = ["--threads", "1", "--epochs", "1", "--hidden", "8", "--format", "json"]


def _ev(**kw):
    base = dict(rows=10_000, episodes=100, discrete=False, n_actions=None, rewards=True,
                length_median=20.0, length_max=30, at_limit=0.05, repeats=0.05)
    return Evidence(**{**base, **kw})


def _saved(store, corpus, model="default"):
    return json.loads((store.corpus(corpus).models_dir / model / "config.json").read_text())


@pytest.fixture
def upright(store, tmp_path):
    """An upright pendulum log collected (``up``) and the same log ingested from a plain NPZ
    (``file``): no trace of the task."""
    from tests.conftest import run_aoc

    s = Store(store)
    data, _ = collect("pendulum-het-upright", steps=2000, seed=0)
    s.write("up", data)
    path = write_plain_npz(data, tmp_path / "log.npz")
    code, _out, err = run_aoc("ingest", str(path), "--name", "file")
    assert code == 0, err
    return s


def test_the_same_log_from_a_file_has_the_same_evidence(upright):
    up, file = (Evidence.of(upright.corpus(n)) for n in ("up", "file"))
    assert up == file
    assert "task" not in json.dumps(upright.corpus("file").manifest["sources"])
    assert up.at_limit > evidence.AT_LIMIT and up.length_max == 200 and not up.discrete


def test_the_evidence_of_each_kind_of_log():
    ward = Evidence.of(_data("ward", episodes=30))
    assert not ward.rewards and ward.discrete
    sepsis = Evidence.of(_data("icu-sepsis", episodes=300))
    assert sepsis.discrete and sepsis.repeats > evidence.REPEATS and sepsis.rewards
    assert sepsis.at_limit < evidence.AT_LIMIT  # patients leave or die: the episodes end
    maze = Evidence.of(_data("maze", episodes=30))
    assert maze.repeats < 0.2 and maze.at_limit < evidence.AT_LIMIT and maze.rewards


def _data(task, **kw):
    return collect(task, seed=0, **kw)[0]


def test_rule_1_mode_from_the_rewards():
    assert decide(_ev(), {})[0]["mode"] == "value"
    out, why = decide(_ev(rewards=False, discrete=True, n_actions=2), {})
    assert out == {"mode": "imitation"} and "no rewards" in why[0]["why"]
    # a mode given is followed: imitation decides nothing else
    assert decide(_ev(), {"mode": "imitation"})[0] == {}


def test_rule_2_a_finite_state_revisited():
    ev = _ev(discrete=True, n_actions=25, repeats=0.93, length_median=6, length_max=73,
             at_limit=0.001)
    out, _ = decide(ev, {})
    assert out == {"mode": "value", "history_length": 0, "value": "fqe", "gamma": 1.0,
                   "residual_cap": evidence.STATE_CAP, "do_no_harm": "off"}
    # the penalty is measured once the row values exist (state_penalty, below)
    from aoc_cli.belief.config import BeliefConfig

    assert evidence.penalises(ev, BeliefConfig(mode="value"), {})
    assert not evidence.penalises(ev, BeliefConfig(mode="value"), {"support_penalty": 1.0})
    assert not evidence.penalises(_ev(discrete=True, n_actions=25), BeliefConfig(), {})
    # the flags given win, and a critic keeps its own targets
    out, _ = decide(ev, {"gamma": 0.9, "support_penalty": 1.0})
    assert "gamma" not in out and "support_penalty" not in out and out["value"] == "fqe"
    assert "value" not in decide(ev, {"belief": "critic"})[0]
    # observations that do not recur: rule 7 instead, rule 2 over the log's nearest rows
    # (the values by FQE over them, a state belief, undiscounted), and the clinicians' likely
    # action kept unless a bound beats its own
    out, why = decide(_ev(discrete=True, n_actions=25), {})
    assert out == {"mode": "value", "value": "neighbours", "history_length": 0, "gamma": 1.0,
                   "do_no_harm": "on"}
    assert "rule 7" in why[-1]["why"] and why[-1]["setting"] == "do_no_harm"
    # a time limit keeps rule 3's discount; a critic keeps its own targets
    limited = decide(_ev(discrete=True, n_actions=25, at_limit=0.98), {})[0]
    assert limited["value"] == "neighbours" and limited["gamma"] < 1.0
    assert "value" not in decide(_ev(discrete=True, n_actions=25), {"belief": "critic"})[0]
    # continuous actions: no rule 7
    assert "do_no_harm" not in decide(_ev(discrete=False), {})[0]


def _noise_by_hand(obs, actions, rewards, starts, values, gamma, censored=None):
    """The pooled within-pair sd of the one-step targets, row by row."""
    keyed = [tuple(o) for o in np.asarray(obs).reshape(len(rewards), -1).tolist()]
    at = {}
    for key, v in zip(keyed, values):
        at.setdefault(key, []).append(v)
    last = set((np.asarray(starts[1:]) - 1).tolist())
    cut = set() if censored is None else \
        {int(starts[e + 1] - 1) for e in np.flatnonzero(censored)}
    groups = {}
    for i in range(len(rewards)):
        if i in cut:
            continue
        y = rewards[i] + (0.0 if i in last else gamma * float(np.mean(at[keyed[i + 1]])))
        groups.setdefault((keyed[i], int(actions[i])), []).append(y)
    ss = sum(float(np.sum((np.array(g) - np.mean(g)) ** 2)) for g in groups.values())
    dof = sum(len(g) - 1 for g in groups.values())
    return (np.sqrt(ss / dof) if dof else 0.0), dof


@pytest.mark.parametrize("seed", range(6))
def test_the_one_step_noise_is_the_pooled_sd_of_the_targets_within_each_pair(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 200))
    obs = rng.integers(0, 4, size=(n, 2)).astype(np.float32)      # few states: pairs repeat
    actions = rng.integers(0, 3, size=n)
    rewards = rng.normal(size=n) * (seed % 2)                       # zero rewards too
    cuts = np.sort(rng.choice(np.arange(1, n), size=min(n - 1, 5), replace=False))
    starts = np.concatenate([[0], cuts, [n]])
    values = rng.normal(size=n)
    gamma = float(rng.choice([1.0, 0.9]))
    censored = rng.random(len(starts) - 1) < 0.3 if seed >= 3 else None
    got = evidence.one_step_noise(obs, actions, rewards, starts, values, gamma, censored)
    want = _noise_by_hand(obs, actions, rewards, starts, values, gamma, censored)
    assert got[1] == want[1]
    assert got[0] == pytest.approx(want[0], rel=1e-12, abs=1e-15)


def test_the_one_step_noise_is_zero_where_nothing_repeats_and_the_bound_is_bonferronis():
    obs = np.arange(6, dtype=np.float32)[:, None]
    assert evidence.one_step_noise(obs, np.zeros(6), np.ones(6), np.array([0, 3, 6]),
                                   np.ones(6), 1.0) == (0.0, 0)
    from scipy.stats import norm

    for k in (1, 2, 25):
        assert evidence.lower_bound_z(k) == pytest.approx(norm.ppf(1 - 0.05 / k), rel=1e-9)
    assert evidence.lower_bound_z(25, 0.9) < evidence.lower_bound_z(25)


def test_rule_2s_penalty_is_the_bound_in_the_controllers_units():
    data = _data("icu-sepsis", episodes=300)
    values = np.random.default_rng(0).random(data.n_rows)
    z, why = evidence.state_penalty(data, values, 1.0)
    noise, dof = evidence.one_step_noise(data.observations, data.actions, data.rewards,
                                         data.episode_starts, values, 1.0)
    assert dof > 0 and why["value"] == z
    assert z == pytest.approx(evidence.lower_bound_z(25) * noise / np.std(values), abs=5e-4)
    assert "simultaneous 95% lower bound" in why["why"] and "25 actions" in why["why"]
    flat, why = evidence.state_penalty(data, np.ones(data.n_rows), 1.0)
    assert flat is None and "no noise to bound" in why["why"]


def test_rule_3_gamma_from_a_time_limit():
    out, why = decide(_ev(length_median=200, length_max=200, at_limit=0.98), {})
    assert out["gamma"] == 0.9 and "time limit" in why[-1]["why"]
    assert evidence.horizon_gamma(200) == pytest.approx(0.9, abs=1e-15)
    assert evidence.horizon_gamma(10_000) == evidence.GAMMA_MAX
    assert evidence.horizon_gamma(10) == evidence.GAMMA_MIN
    assert "gamma" not in decide(_ev(), {})[0]  # episodes that end by themselves
    assert "gamma" not in decide(_ev(at_limit=0.98, length_max=200), {"belief": "critic"})[0]


def test_rule_4_epsilon_is_the_median_share_rounded_up_to_a_tenth():
    assert epsilon_rule.rule(np.array([0.0, 0.04, 0.2])) == 0.1
    assert epsilon_rule.rule(np.array([0.1, 0.11, 0.9])) == 0.2
    assert epsilon_rule.rule(np.array([0.2, 0.225, 0.5])) == 0.3
    assert epsilon_rule.rule(np.array([0.1, 0.2, 0.3])) == 0.2  # a tenth exactly stays
    assert epsilon_rule.rule(np.array([0.9, 0.9, 0.9])) == epsilon_rule.HIGH


def test_aoc_train_decides_records_and_shows_the_settings_of_a_plain_file(aoc, upright):
    code, out, err = aoc("train", "file", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    decided = {r["setting"]: r["value"] for r in metrics["settings"]["decided"]}
    assert decided["gamma"] == 0.9 and decided["mode"] == "value"
    assert 0.1 <= decided["epsilon"] <= 0.5  # decided on held-out episodes after training
    assert metrics["controller"] == {"epsilon": decided["epsilon"],
                                     "k": 2 * (_saved(upright, "file")["config"]
                                               ["belief_dim"] + 1)}
    assert metrics["settings"]["evidence"]["at_limit"] > evidence.AT_LIMIT
    said = " ".join(err.split())
    assert "gamma 0.9: 100% of the episodes stop at 200 steps (a time limit)" in said
    assert "epsilon 0." in said and "held-out episodes" in said
    saved = _saved(upright, "file")
    assert saved["config"]["gamma"] == 0.9 and saved["value"]["gamma"] == 0.9
    assert saved["metrics"]["controller"] == metrics["controller"]
    # the collected log decides the same
    code, out, err = aoc("train", "up", *QUICK)
    assert code == 0, err
    def plain(m):
        return [{k: v for k, v in r.items() if k != "seconds"} for r in m["settings"]["decided"]]

    assert plain(json.loads(out)) == plain(metrics)


@pytest.mark.parametrize("args, gamma, controller", [
    (["--gamma", "0.99"], 0.99, True), (["--paper"], 0.99, False),
    (["--belief", "dynamics"], 0.99, False), (["--no-select"], 0.9, False)])
def test_a_flag_paper_or_no_select_overrides_the_evidence(aoc, upright, args, gamma,
                                                           controller):
    code, out, err = aoc("train", "file", "--model", "m", *args, *QUICK)
    assert code == 0, err
    assert _saved(upright, "file", "m")["config"]["gamma"] == gamma
    assert ("epsilon" in json.loads(out).get("controller", {})) == controller
    if "--paper" in args:
        assert "settings" not in json.loads(out) and "decides what no flag gave" not in err


def test_a_reward_free_file_trains_in_imitation_mode(aoc, store, tmp_path):
    from tests.conftest import run_aoc

    path = write_plain_npz(_data("ward", episodes=40), tmp_path / "ward.npz")
    code, _out, err = run_aoc("ingest", str(path), "--name", "w")
    assert code == 0, err
    code, out, err = aoc("train", "w", "--history-length", "0", "--hidden", "8",
                         "--weight-decay", "0", "--threads", "1", "--epochs", "1",
                         "--format", "json")
    assert code == 0, err
    assert json.loads(out)["mode"] == "imitation"
    assert "mode imitation: the log has no rewards" in " ".join(err.split())


def test_the_controller_settings_travel_with_the_model(aoc, store, tmp_path):
    """Decided at train, saved with the model, used by every command that decides unless its
    own flag is given; a ControllerConfig given whole is taken as it is."""
    import aoc_cli
    from aoc_cli.control import ControllerConfig

    s = Store(store)
    path = write_plain_npz(_data("icu-sepsis", episodes=120), tmp_path / "icu.npz")
    from tests.conftest import run_aoc

    assert run_aoc("ingest", str(path), "--name", "icu")[0] == 0
    # rule 2's controller (--no-select: not chosen on held-out episodes, tests/training/
    # test_controller_selection.py) and the k rule's k
    # (--value return: rule 2's controller does not depend on how the values were computed,
    # and fitted Q evaluation costs a minute here; tests/control/test_icu_sepsis_quality.py
    # trains with no flags)
    code, out, err = aoc("train", "icu", "--no-select", "--value", "return", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    z = metrics["settings"]["support_penalty"]["value"]
    assert metrics["controller"] == {"residual_cap": 0.01, "support_penalty": z,
                                     "k": 2 * (_saved(s, "icu")["config"]["belief_dim"] + 1),
                                     "do_no_harm": "off"}
    assert 1.0 < z < 20.0  # the log's noise over the values' spread, times z_25 = 2.88
    assert _saved(s, "icu")["config"]["history_length"] == 0
    assert aoc("index", "icu", "--format", "json")[0] == 0
    own = aoc_cli.open_session("icu", store=store).controller.config
    assert (own.residual_cap, own.support_penalty, own.epsilon, own.do_no_harm) == \
        (0.01, z, 0.5, "off")
    flag = aoc_cli.open_session("icu", store=store,
                                controller={"support_penalty": 0.0}).controller.config
    assert (flag.residual_cap, flag.support_penalty) == (0.01, 0.0)
    from aoc_cli.control import open_session

    whole = open_session(s.corpus("icu"), config=ControllerConfig()).controller.config
    assert whole == ControllerConfig()
    # aoc evaluate decides with them (and takes --residual-cap): the cap binds on the log's
    # own steps, so dropping it changes the decisions
    base = ["evaluate", "icu", "--data", "icu", "--baselines", "none", "--ope", "none",
            "--format", "json"]
    code, out, err = aoc(*base)
    assert code == 0, err
    code, loose, err = aoc(*base, "--residual-cap", "1000", "--support-penalty", "0")
    assert code == 0, err
    assert json.loads(out) != json.loads(loose)


def test_the_held_out_epsilon_shows_on_the_progress_bar(store):
    from aoc_cli.training.fit import train_corpus

    corpus = Store(store).write("m", _data("maze", episodes=30))
    labels = []
    trained = train_corpus(corpus, threads=1, max_epochs=1, hidden=8,
                           progress=lambda done, total=None, label=None: labels.append(label))
    assert any(label and label.startswith("deciding epsilon") for label in labels)
    assert 0.1 <= trained.metrics["controller"]["epsilon"] <= 0.5
