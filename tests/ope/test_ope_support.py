"""What the log can support (aoc_cli.ope.support, aoc_cli.ope.estimators): an estimate that
cannot be computed is null, never 0, and FQE stays when importance sampling is refused;
undefined bootstrap replicates are left out and counted; weights that overflow a float give
the same estimates; the rule's reasons and the table's cell; V(policy) - V(behaviour) with
an interval paired over the same resamples, and the verdict line."""

import json

import numpy as np
import pytest

from aoc_cli.ope import estimators as ope
from aoc_cli.ope.fqe import student_quantile
from aoc_cli.ope.evaluate_block import OPESettings
from aoc_cli.ope.support import cell, min_ess, outside_returns, refusal, verdict
from aoc_cli.ope.value import policy_value
from tests.ope.mdps import SmallMDP


def _exact_fqe(mdp, pi, data, refits=10, seed=0):
    """An FQE record (as :func:`aoc_cli.ope.fqe.fqe_policies` returns it, with refits) whose
    Q is the exact one: the direct method without a model's error."""
    _, q = mdp.exact(pi)
    st, starts = data["state"], data["starts"]
    e = len(starts) - 1
    v0 = (pi * q).sum(1)[st[starts[:-1]]]                                   # (E,)
    counts = np.random.default_rng(seed).multinomial(e, np.full(e, 1 / e), size=refits)
    reps = counts @ v0 / e
    half = student_quantile(refits - 1) * reps.std(ddof=1)
    return {"q": q[st], "estimate": float(v0.mean()), "fit_estimate": float(v0.mean()),
            "low": float(v0.mean() - half), "high": float(v0.mean() + half),
            "replicates": reps, "counts": counts, "steps": 100, "refit_steps": 20}


def test_a_policy_no_logged_episode_follows_is_null_and_fqe_still_answers():
    """The behaviour never takes action 0, the policy always does: every weight is 0. PDWIS
    and WDR are undefined, null with a reason, never 0; FQE needs no overlap and stays."""
    mdp = SmallMDP.random(n_states=6, seed=5, end=0.3)
    s, a = mdp.P.shape[:2]
    pi_b = np.random.default_rng(5).dirichlet(np.ones(a - 1), size=s)
    pi_b = np.concatenate([np.zeros((s, 1)), pi_b], axis=1)
    pi_e = np.eye(a)[np.zeros(s, int)]
    truth, _ = mdp.exact(pi_e)
    data = mdp.sample(pi_b, 400, seed=6)
    log = ope.Log(data["starts"], data["reward"])
    assert np.isnan(ope.pdwis(log, np.zeros(len(data["reward"]))))
    fqe = _exact_fqe(mdp, pi_e, data)
    rec = policy_value(log, None, data["action"], data["propensity"], pi_e[data["state"]], a,
                       OPESettings(n_boot=200), fqe=fqe)
    for name in ("pdwis", "wdr"):
        assert rec["policy_value"][name] == {
            "estimate": None, "low": None, "high": None,
            "reason": "undefined: no logged episode follows the policy"}
        assert rec["improvement"][name]["estimate"] is None
    assert rec["ess"] == 0.0
    shown = rec["policy_value"]["fqe"]
    assert shown["estimate"] == pytest.approx(truth, abs=0.05)
    assert shown["low"] <= truth <= shown["high"]
    assert rec["verdict"].endswith("(FQE): shown") or "(FQE): not shown" in rec["verdict"]
    json.dumps(rec["policy_value"], allow_nan=False)           # null, not NaN


def test_undefined_replicates_are_left_out_and_counted_not_taken_as_zero():
    """One episode of 30 follows the policy to its end (reward 1); in a resample without it
    PDWIS is undefined. The interval holds the defined replicates (all 1), and the share
    undefined is about (29/30)^30 = 0.36; the old code put those at 0."""
    starts = np.arange(31)
    rewards = np.zeros(30)
    rewards[0] = 1.0
    rho = np.zeros(30)
    rho[0] = 2.0
    est = ope.bootstrap(ope.Log(starts, rewards), {"pdwis": ("pdwis", rho)}, n_boot=2000)
    e = est["pdwis"]
    assert e.estimate == e.low == e.high == 1.0
    assert e.undefined == pytest.approx((29 / 30) ** 30, abs=0.04)
    diag = ope.diagnostics(ope.Log(starts, rewards), rho)
    assert refusal("pdwis", diag, 30, e.undefined, e.estimate).startswith("ESS 1.0 of 30")


def test_weights_past_a_floats_range_give_the_same_estimates():
    """400 steps of ratio 10 (10^400: inf in float64) against the same log with every ratio
    divided by 10: the estimators are ratios of one step's weights, so the same values."""
    t, e = 400, 4
    rng = np.random.default_rng(0)
    starts = np.arange(0, e * t + 1, t)
    rewards = rng.random(e * t)
    small = rng.choice([1.0, 0.5], size=e * t)
    q, v = rng.random(e * t), rng.random(e * t)
    log = ope.Log(starts, rewards, gamma=0.99)
    big = small * 10.0
    assert not np.isfinite(np.prod(big[:t]))
    assert ope.pdwis(log, big) == pytest.approx(ope.pdwis(log, small), rel=1e-12)
    assert ope.wdr(log, big, q, v) == pytest.approx(ope.wdr(log, small, q, v), rel=1e-12)
    assert ope.ess(log, big) == pytest.approx(ope.ess(log, small), rel=1e-12)
    assert np.isfinite(ope.pdwis(log, big))


def test_the_rule_and_the_table_cell():
    ok = {"ess": 900.0, "reached": 0.97, "first_step_weight": 1.01,
          "first_step_weight_se": 0.02}
    assert refusal("pdwis", ok, 3000) is None and refusal("wdr", ok, 3000) is None
    why = refusal("pdwis", {**ok, "ess": 4.6}, 3000)
    assert why == "ESS 4.6 of 3,000 (the rule asks 500)"
    assert cell({"estimate": None, "reason": why}) == "not estimable: ESS 4.6 of 3,000"
    assert cell({"estimate": 0.8, "low": 0.7, "high": 0.9}) == "0.8000 [0.7000, 0.9000]"
    assert min_ess(200) == min_ess(20000) == 500.0
    unreached = {**ok, "reached": 0.6}
    assert refusal("pdwis", unreached, 3000).startswith("the log follows 60% of the policy's")
    assert refusal("wdr", unreached, 3000) is None         # WDR leaves that share to its Q
    assert "undefined" in refusal("wdr", ok, 3000, undefined=0.2)
    assert refusal("wdr", {**ok, "first_step_weight": 1.4}, 3000).startswith(
        "mean first-step weight 1.4")
    assert refusal("pdwis", ok, 3000, estimate=float("nan")).startswith("undefined")


def test_the_verdict_line():
    d = lambda e, lo, hi: {"estimate": e, "low": lo, "high": hi}
    no = {"estimate": None, "low": None, "high": None, "reason": "ESS 4.6 of 3,000 (x)"}
    assert verdict({"pdwis": no, "fqe": d(0.019, -0.004, 0.041)}) == (
        "better than the logged behaviour by 0.019 [-0.004, 0.041] (FQE): not shown by this "
        "log")
    assert verdict({"wdr": d(0.03, 0.01, 0.05), "fqe": no}) == (
        "better than the logged behaviour by 0.030 [0.010, 0.050] (WDR): shown")
    assert verdict({"fqe": d(-0.03, -0.05, -0.01)}) == (
        "worse than the logged behaviour by 0.030 [0.010, 0.050] (FQE): shown")
    # a negative difference reads "worse ... by" its magnitude, shown or not
    assert verdict({"fqe": d(-0.280, -0.568, 0.008)}) == (
        "worse than the logged behaviour by 0.280 [-0.008, 0.568] (FQE): not shown by this "
        "log")
    assert verdict({"pdwis": no, "wdr": no}) == (
        "better or worse than the logged behaviour: not estimable from this log (ESS 4.6 of "
        "3,000)")


def test_an_estimate_outside_the_returns_range_is_withheld_with_its_reason():
    """A survival probability above 1 (FQE gave 1.696 on a noisy cohort) or an interval end
    below the worst return is never shown; a float's rounding at the edge is."""
    assert outside_returns({"estimate": 0.9, "low": 0.8, "high": 1.0}, 0.0, 1.0) is None
    assert outside_returns({"estimate": 1.0, "low": 1.0, "high": 1.0 + 1e-12}, 0.0, 1.0) is None
    why = outside_returns({"estimate": 1.696, "low": 1.4, "high": 1.99}, 0.0, 1.0)
    assert why.startswith("outside the range of the log's returns (1.696 [1.4, 1.99] for "
                          "returns in [0, 1]")
    assert outside_returns({"estimate": 0.05, "low": -0.01, "high": 0.1}, 0.0, 1.0)
    assert outside_returns({"estimate": float("nan"), "low": 0, "high": 1}, 0.0, 1.0)
    assert outside_returns({"estimate": None, "reason": "x"}, 0.0, 1.0) is None


def test_an_fqe_value_above_every_return_is_withheld_and_the_verdict_reads_the_next():
    """FQE's Q extrapolated off the log: its value 1.7 of a survival in [0, 1] is withheld
    (value and difference, with the reason) and the verdict reads WDR or says why not."""
    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    pi_b = np.random.default_rng(1).dirichlet(np.full(a, 2.0), size=s)
    data = mdp.sample(pi_b, 600, seed=3)
    log = ope.Log(data["starts"], data["reward"])
    returns = log.returns()
    assert returns.min() >= 0 and returns.max() <= 1
    fqe = _exact_fqe(mdp, pi_b, data)
    shift = 1.7 - fqe["estimate"]
    fqe = {**fqe, "q": fqe["q"] + shift, "estimate": 1.7, "low": fqe["low"] + shift,
           "high": fqe["high"] + shift, "replicates": fqe["replicates"] + shift}
    rec = policy_value(log, None, data["action"], data["propensity"], pi_b[data["state"]], a,
                       OPESettings(estimators=("fqe",), n_boot=200), fqe=fqe)
    assert rec["policy_value"]["fqe"]["estimate"] is None
    assert rec["policy_value"]["fqe"]["reason"].startswith("outside the range of the log's")
    assert rec["improvement"]["fqe"]["estimate"] is None
    assert rec["verdict"].startswith("better or worse than the logged behaviour: not estimable "
                                     "from this log (outside the range of the log's returns")
    json.dumps(rec, default=lambda x: None, allow_nan=False)


def test_the_behaviour_itself_improves_on_itself_by_exactly_zero():
    """Paired: PDWIS of the behaviour is the mean return in every resample, so the
    difference is 0 in each, its interval [0, 0]; unpaired it would be as wide as both."""
    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    pi_b = np.random.default_rng(1).dirichlet(np.full(a, 2.0), size=s)
    data = mdp.sample(pi_b, 600, seed=3)
    log = ope.Log(data["starts"], data["reward"])
    rec = policy_value(log, None, data["action"], data["propensity"], pi_b[data["state"]], a,
                       OPESettings(estimators=("pdwis",), n_boot=300), fqe=None)
    gain = rec["improvement"]["pdwis"]
    assert abs(gain["estimate"]) < 1e-12
    assert abs(gain["low"]) < 1e-12 and abs(gain["high"]) < 1e-12
    value = rec["policy_value"]["pdwis"]
    assert value["high"] - value["low"] > 0.05
    assert rec["verdict"] == ("better than the logged behaviour by 0.000 [-0.000, 0.000] "
                              "(PDWIS): not shown by this log") or \
        rec["verdict"].endswith("(PDWIS): not shown by this log")


def test_the_improvement_of_a_better_policy_covers_the_true_difference():
    """A greedy policy on a small MDP, 20,000 behaviour episodes: each estimator's paired
    interval for V(policy) - V(behaviour) covers the exact difference, PDWIS's and WDR's
    narrower than the two values' intervals put end to end, and FQE's is its refits' less the
    same resamples' mean returns."""
    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    rng = np.random.default_rng(1)
    pi_b = rng.dirichlet(np.full(a, 2.0), size=s)
    _, q_b = mdp.exact(pi_b)
    best = np.eye(a)[np.argmax(mdp.P[:, :, s] + mdp.P[:, :, :s] @ np.full(s, 0.5), axis=1)]
    pi_e = 0.6 * best + 0.4 * pi_b
    truth = mdp.exact(pi_e)[0] - mdp.exact(pi_b)[0]
    data = mdp.sample(pi_b, 20000, seed=7)
    log = ope.Log(data["starts"], data["reward"])
    fqe = _exact_fqe(mdp, pi_e, data)
    rec = policy_value(log, None, data["action"], data["propensity"], pi_e[data["state"]], a,
                       OPESettings(n_boot=300), fqe=fqe)
    behaviour = ope.bootstrap(log, {"m": ("mean", log.returns())}, n_boot=300)["m"]
    for name, gain in rec["improvement"].items():
        assert gain["low"] <= truth <= gain["high"], (name, gain, truth)
        if name == "fqe":
            continue
        value = rec["policy_value"][name]
        unpaired = (value["high"] - value["low"]) + (behaviour.high - behaviour.low)
        assert gain["high"] - gain["low"] < unpaired
    returns = log.returns()
    diffs = fqe["replicates"] - fqe["counts"] @ returns / len(returns)
    half = student_quantile(9) * diffs.std(ddof=1)
    assert rec["improvement"]["fqe"]["high"] - rec["improvement"]["fqe"]["low"] == \
        pytest.approx(2 * half, rel=1e-9)
    assert truth > 0.02 and rec["verdict"].endswith("(FQE): shown")


def test_a_small_ess_is_warned_of_only_beside_a_shown_importance_sampling_estimate():
    """The withheld cells already say "not estimable: ESS ..."; the warning on stderr is left
    for a shown PDWIS or WDR whose ESS is small (a rule given other settings)."""
    from aoc_cli.ope.evaluate_block import warnings_for

    fqe = {"estimate": 0.8, "low": 0.78, "high": 0.82}
    withheld_is = {"ess": 4.6, "policy_value": {"pdwis": {"estimate": None, "reason": "ESS"},
                                                "wdr": {"estimate": None, "reason": "ESS"},
                                                "fqe": fqe}}
    assert warnings_for("aoc", withheld_is, 3000) == []
    shown_is = {"ess": 4.6, "policy_value": {"pdwis": {"estimate": 0.79, "low": 0.7,
                                                       "high": 0.9}, "fqe": fqe}}
    out = warnings_for("aoc", shown_is, 3000)
    assert len(out) == 1 and "effective sample size 4.6 of 3000" in out[0]


def _noisy_two_step_log(episodes=300, seed=0, noise=0.3):
    """Two-step stays over 3 latent states seen through Gaussian noise (no observation
    repeats); the clinicians give dose 0 or 1, never 2 or 3; the outcome at the second step.
    Returns (starts, rewards, observations, actions, survival table (3, 4))."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(0, 2, size=(3, 4))
    surv = np.array([[0.8, 0.75, 0.6, 0.7]] * 3)
    obs, act, rew = [], [], []
    for _ in range(episodes):
        s = rng.integers(0, 3)
        a1 = rng.integers(0, 2)
        obs.append(centres[s] + rng.normal(0, noise, 4)); act.append(a1); rew.append(0.0)
        s2 = (s + a1) % 3
        a2 = rng.integers(0, 2)
        obs.append(centres[s2] + rng.normal(0, noise, 4)); act.append(a2)
        rew.append(float(rng.random() < surv[s2, a2]))
    starts = np.arange(0, 2 * episodes + 1, 2)
    return starts, np.asarray(rew), np.asarray(obs), np.asarray(act), surv


def test_fqe_extrapolating_off_a_continuous_log_is_not_a_confident_verdict():
    """The issue's 300-stay case in small: a policy that gives a dose the clinicians never
    gave, on noisy features; FQE's Q there is its network's extrapolation and came out low and
    narrow (0.137 [0.035, 0.239] against a truth near 0.7): "worse ... shown", a confident
    wrong verdict. With the log's neighbourhoods (no episode near any step took the dose) the
    interval is widened by the share hardly held, and the verdict is not shown."""
    from aoc_cli.index.search.neighbourhood import Neighbourhood

    starts, rewards, obs, logged, surv = _noisy_two_step_log()
    log = ope.Log(starts, rewards)
    n = len(logged)
    policy = np.full(n, 3)                         # a dose the log never holds
    e = len(starts) - 1
    counts = np.random.default_rng(0).multinomial(e, np.full(e, 1 / e), size=10)
    reps = 0.137 + np.random.default_rng(1).normal(0, 0.045, 10)
    fqe = {"q": np.full((n, 4), 0.137), "estimate": 0.137, "fit_estimate": 0.14,
           "low": 0.035, "high": 0.239, "replicates": reps, "counts": counts, "steps": 100,
           "refit_steps": 20}
    settings = OPESettings(estimators=("fqe",), n_boot=200)
    propensity = np.full(n, 0.5)
    before = policy_value(log, None, logged, propensity, policy, 4, settings, fqe=fqe)
    truth = surv[0, 3] - log.returns().mean()      # dose 3 at the last step: 0.7 vs ~0.77
    assert before["verdict"].startswith("worse than the logged behaviour by") and \
        before["verdict"].endswith("(FQE): shown")
    assert before["improvement"]["fqe"]["high"] < truth      # confidently wrong
    episode = np.repeat(np.arange(e), 2)
    held = Neighbourhood(obs, logged, episode, 4).at(obs).episodes
    assert (held[:, 2:] == 0).all() and (held[:, :2] >= 3).mean() > 0.9
    after = policy_value(log, None, logged, propensity, policy, 4, settings, fqe=dict(fqe),
                         held=held)
    assert after["support"]["hardly_held"] == 1.0
    assert after["policy_value"]["fqe"]["estimate"] is None
    assert after["policy_value"]["fqe"]["reason"].startswith("the log hardly holds 100%")
    assert "shown" not in after["verdict"].replace("not shown", "")
    # a policy the log holds is shown, its interval widened only by its thin share
    mostly = np.where(np.arange(n) % 10 == 0, 3, logged)
    fqe_near = {**fqe, "estimate": 0.77, "low": 0.74, "high": 0.80,
                "replicates": reps - 0.137 + 0.77}
    shown = policy_value(log, None, logged, propensity, mostly, 4, settings,
                         fqe=dict(fqe_near), held=held)
    share = shown["support"]["hardly_held"]
    assert 0.05 < share < 0.2
    widened = shown["policy_value"]["fqe"]
    returns = log.returns()
    assert widened["low"] == pytest.approx(0.74 - share * np.ptp(returns), abs=1e-12)
    assert widened["high"] == pytest.approx(0.80 + share * np.ptp(returns), abs=1e-12)
    assert any("hardly holds" in note for note in shown["notes"])
