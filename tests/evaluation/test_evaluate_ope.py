"""`aoc evaluate`'s offline policy evaluation (value mode): the figures are the estimators'
on the decisions, the JSON keys, the propensities' source, and bad input (a log without
rewards, a zero propensity, a policy that never takes the logged action) as one line and
exit 2. Deciding each distinct observation once gives the per-step decisions."""

import json

import numpy as np
import pytest

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli.control import ControllerConfig, open_session
from aoc_cli.index import build_index
from aoc_cli.envs import collect
from aoc_cli.errors import AocError
from aoc_cli.evaluation.context import EvalContext, episode_rows
from aoc_cli.evaluation.score import _value, _value_distinct, score_log
from aoc_cli.ope import estimators as ope
from aoc_cli.ope.evaluate_block import OPESettings
from aoc_cli.store import Store
from tests.conftest import run_in_process


@pytest.fixture(scope="module")
def sepsis(tmp_path_factory):
    root = tmp_path_factory.mktemp("sepsis-ope")
    store = Store(root)
    store.write("icu", collect("icu-sepsis", episodes=300, seed=0)[0])
    held = collect("icu-sepsis", episodes=150, seed=1)[0]
    store.write("held", held)
    corpus = store.corpus("icu")
    small = dict(history_length=0, hidden=32, belief_dim=4, max_epochs=3, threads=1, seed=0)
    train_model(corpus, BeliefConfig(**small), "default")
    build_index(corpus, "default")
    return root, store, held


def _session(store):
    return open_session(store.corpus("icu"), config=ControllerConfig())


def test_policy_value_is_the_estimators_on_the_decisions(sepsis):
    _root, store, _ = sepsis
    held = store.corpus("held")
    settings = OPESettings(estimators=("pdwis", "wdr"), n_boot=200, fqe_steps=200)
    summary, res = score_log(_session(store), held, ["bc"], ope=settings)
    log = ope.Log(held.episode_starts, held.rewards)
    rho = ope.ratios((res.decided == held.actions).astype(float), held.column("propensity"))
    assert summary["ess"] == pytest.approx(ope.ess(log, rho), abs=1e-9)
    # 150 episodes: an ESS under the rule's 500, so PDWIS and WDR are withheld, with why
    for name in ("pdwis", "wdr"):
        assert summary["policy_value"][name] == {
            "estimate": None, "low": None, "high": None,
            "reason": f"ESS {summary['ess']:,.1f} of 150 (the rule asks 500)"}
    assert summary["verdict"].startswith(
        "better or worse than the logged behaviour: not estimable")
    assert summary["support"]["reached"] <= 1.0
    assert len(summary["support"]["ess_per_step"]) == np.diff(held.episode_starts).max()
    assert summary["behaviour_value"]["estimate"] == pytest.approx(
        np.mean(held.episode_returns()), abs=1e-12)
    assert summary["ope"]["propensity"] == "column 'propensity' of 'held'"
    bc = summary["baselines"]["bc"]
    rho_bc = ope.ratios((res.baselines["bc"]["decided"] == held.actions).astype(float),
                        held.column("propensity"))
    assert bc["ess"] == pytest.approx(ope.ess(log, rho_bc), abs=1e-9)
    assert bc["policy_value"]["pdwis"]["estimate"] is None
    assert bc["policy_value"]["pdwis"]["reason"].startswith(("ESS", "undefined"))
    assert "verdict" in bc and "improvement" in bc


def test_fqe_interval_is_from_refits_and_says_so(sepsis):
    _root, store, _ = sepsis
    held = store.corpus("held")
    settings = OPESettings(estimators=("fqe",), fqe_steps=300, fqe_refits=3)
    summary, res = score_log(_session(store), held, [], ope=settings)
    e = summary["policy_value"]["fqe"]
    # 300 steps on 150 episodes: FQE may be off on the logged behaviour, and then withheld
    off = summary["behaviour_value"]["fqe"]
    low, high = summary["behaviour_value"]["low"], summary["behaviour_value"]["high"]
    if low <= off <= high:
        assert e["low"] < e["estimate"] < e["high"]
        gain = summary["improvement"]["fqe"]
        assert gain["estimate"] == pytest.approx(
            e["estimate"] - summary["behaviour_value"]["estimate"], abs=1e-12)
        assert "(FQE)" in summary["verdict"]
    else:
        assert e["estimate"] is None and e["reason"].startswith(
            f"FQE off on the logged behaviour ({off:.4g}, outside its mean return's")
    assert summary["ope"]["fqe_refits"] == 3
    note = [n for n in summary["ope"]["notes"] if n.startswith("fqe:")]
    one, _ = score_log(_session(store), held, [], ope=OPESettings(
        estimators=("fqe",), fqe_steps=300, fqe_refits=0))
    reason = one["policy_value"]["fqe"]["reason"]      # one fit: withheld, its value said
    assert one["policy_value"]["fqe"]["estimate"] is None
    assert reason.startswith("one fit (fqe_refits 0): its interval would leave the model's "
                             "own error out; its start values give ")
    fit = float(reason.rsplit(" ", 1)[1])               # the same full fit, without refits
    assert note == [f"fqe: the estimate is the mean of 3 refits' start values (bagged; one "
                    f"fit's: {fit:.4g}), the interval +- 4.3 sd of the refits' estimates "
                    "(Student's t, 2 degrees of freedom), each "
                    "refit on the log's episodes resampled with replacement, 300 steps on from "
                    "the full fit's 300-step weights (the refits' sampling and training "
                    "error is in it; cost 4.0x one fit)"]
    if e["estimate"] is not None:
        assert abs(e["estimate"] - fit) > 1e-6


def test_cli_fqe_refits_reach_the_estimator(sepsis, capsys):
    root, _store, _ = sepsis
    code, out, _err = run_in_process(capsys, "--store", str(root), "evaluate", "icu", "--data",
                                     "held", "--baselines", "none", "--ope", "fqe",
                                     "--fqe-steps", "200", "--fqe-refits", "2", "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert doc["ope"]["fqe_refits"] == 2
    assert any(n.startswith("fqe: the estimate is the mean of 2 refits' start values")
               for n in doc["ope"]["notes"])


def test_fqe_refits_of_one_is_one_line(sepsis, capsys):
    root, _store, _ = sepsis
    code, out, err = _ope_cli(capsys, root, "held", "--fqe-refits", "1")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == ["aoc: error: --fqe-refits must be 0 or at least 2, got 1"]


def test_without_a_propensity_column_an_imitation_model_estimates_them(sepsis, tmp_path):
    _root, store, held = sepsis
    bare = type(held)(**{**held.__dict__, "columns": {}})
    store.write("bare", bare)
    settings = OPESettings(estimators=("pdwis",), n_boot=100)
    summary, _ = score_log(_session(store), store.corpus("bare"), [], ope=settings)
    assert summary["ope"]["propensity"].startswith("estimated: multinomial logistic "
                                                   "regression of the logged action")
    assert 0 < summary["ess"] <= held.n_episodes
    model = summary["ope"]["propensity_model"]
    assert model["folds"] == 3 and 0 <= model["ece"] < 0.1
    assert model["log_loss"] < model["log_loss_frequencies"]


def test_each_distinct_observation_is_decided_once_with_the_per_step_results(sepsis):
    _root, store, _ = sepsis
    ctx = EvalContext.build(_session(store), store.corpus("held"), ["bc", "knn"])
    rows = episode_rows(ctx.data_starts, np.arange(40))
    ep = np.searchsorted(ctx.data_starts, rows, side="right") - 1
    args = (rows, ep, ctx.data_obs[rows], ctx.data.history(rows, 0), ctx.data_actions[rows])
    per_step, distinct = _value(ctx, *args), _value_distinct(ctx, *args)
    assert np.array_equal(per_step.decided, distinct.decided)
    assert np.allclose(per_step.v_hat, distinct.v_hat, rtol=1e-9, atol=1e-12)
    assert np.allclose(per_step.residual, distinct.residual, rtol=1e-9, atol=1e-12)
    assert np.array_equal(per_step.baselines["bc"]["decided"], distinct.baselines["bc"]["decided"])
    knn = ctx.knn.predict(ctx, args[2], args[4], ep)
    assert np.array_equal(knn["decided"], distinct.baselines["knn"]["decided"])
    assert np.allclose(knn["v_hat"], distinct.baselines["knn"]["v_hat"], atol=1e-12)


def _ope_cli(capsys, root, data, *extra):
    return run_in_process(capsys, "--store", str(root), "evaluate", "icu", "--data", data,
                          "--baselines", "none", "--ope", "pdwis", *extra)


def test_json_has_policy_value_behaviour_value_and_ess(sepsis, capsys):
    root, _store, _ = sepsis
    code, out, _err = _ope_cli(capsys, root, "held", "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert set(doc["policy_value"]["pdwis"]) == {"estimate", "low", "high", "reason"}
    assert doc["policy_value"]["pdwis"]["estimate"] is None       # ESS under 500: withheld
    assert set(doc["improvement"]) == {"pdwis"} and isinstance(doc["verdict"], str)
    assert set(doc["behaviour_value"]) == {"estimate", "low", "high"}
    assert 0 < doc["ess"] <= 150


def test_zero_propensity_of_a_logged_action_is_one_line(sepsis, capsys):
    root, store, held = sepsis
    p = held.columns["propensity"].copy()
    p[3] = 0.0
    store.write("zero", type(held)(**{**held.__dict__, "columns": {**held.columns,
                                                                   "propensity": p}}))
    code, out, err = _ope_cli(capsys, root, "zero")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        "aoc: error: the behaviour propensity of logged step 3 is 0.0: a logged action's "
        "probability must be in (0, 1] (1 such steps)"]


def test_a_propensity_above_one_is_one_line(sepsis, capsys):
    root, store, held = sepsis
    p = held.columns["propensity"].copy()
    p[5] = 1.25
    store.write("above", type(held)(**{**held.__dict__, "columns": {**held.columns,
                                                                    "propensity": p}}))
    code, out, err = _ope_cli(capsys, root, "above")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        "aoc: error: the behaviour propensity of logged step 5 is 1.25: a logged action's "
        "probability must be in (0, 1] (1 such steps)"]


def test_a_propensity_column_the_log_lacks_is_one_line_before_any_step_is_decided(sepsis,
                                                                                 capsys):
    root, _store, _ = sepsis
    code, out, err = _ope_cli(capsys, root, "held", "--propensity", "nosuch")
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "aoc: error: corpus 'held' has no column 'nosuch' for the behaviour's propensities "
        "(--propensity; columns: ")
    assert "propensity" in lines[0] and "Traceback" not in err


def test_a_policy_that_never_takes_the_logged_action_is_null_not_an_error(sepsis, capsys,
                                                                          tmp_path):
    root, store, held = sepsis
    steps = tmp_path / "steps.jsonl"          # the command's own decisions (its task settings)
    code, _, _ = run_in_process(capsys, "--store", str(root), "evaluate", "icu", "--data",
                                "held", "--baselines", "none", "--ope", "none", "--steps",
                                str(steps))
    assert code == 0
    decided = np.array([json.loads(line)["decision"] for line in steps.read_text().splitlines()])
    other = (decided + 1) % 25                 # decisions depend on the observation alone
    store.write("never", type(held)(**{**held.__dict__, "actions": other}))
    code, out, err = _ope_cli(capsys, root, "never", "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert doc["policy_value"]["pdwis"] == {
        "estimate": None, "low": None, "high": None,
        "reason": "undefined: no logged episode follows the policy"}
    assert doc["ess"] == 0.0


def test_a_log_without_rewards_asked_for_ope_is_one_line(sepsis, capsys):
    root, store, held = sepsis
    # a reward-free log whose value model is trained on a column
    train = store.corpus("icu").load()
    corpus = store.write("icu-norew", type(train)(**{**train.__dict__, "rewards": None}))
    train_model(corpus, BeliefConfig(value="state", history_length=0, hidden=16, belief_dim=4,
                                     max_epochs=1, threads=1, seed=0), "default")
    build_index(corpus, "default")
    store.write("norew", type(held)(**{**held.__dict__, "rewards": None}))
    code, out, err = run_in_process(capsys, "--store", str(root), "evaluate", "icu-norew",
                                    "--data", "norew", "--baselines", "none", "--ope", "pdwis")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        "aoc: error: corpus 'norew' has no rewards: offline policy evaluation needs the logged "
        "rewards; use --ope none"]


def test_continuous_actions_asked_for_ope_are_refused_before_any_step_is_decided(tmp_path):
    store = Store(tmp_path)
    corpus = store.write("pend", collect("pendulum-het", steps=1200, seed=0)[0])
    train_model(corpus, BeliefConfig(history_length=0, hidden=16, belief_dim=4, max_epochs=1,
                                     threads=1, seed=0), "default")
    build_index(corpus, "default")
    decided = []
    with pytest.raises(AocError, match="offline policy evaluation needs discrete actions"):
        score_log(open_session(corpus, config=ControllerConfig(candidates=8)), corpus,
                  baselines=[], progress=lambda done, total: decided.append(done),
                  ope=OPESettings(estimators=("pdwis",)))
    assert decided == []


def test_an_fqe_models_held_out_target_is_the_behaviours_fqe_kept_beside_the_log(
        sepsis, monkeypatch):
    """For fqe values, value_r2's held-out target is the logged behaviour's Q by the OPE's FQE
    at its default settings: the OPE's own fit when it ran at the model's discount and those
    settings, kept beside the log and read back by a later evaluate; fitted alone at another
    discount or when the OPE's FQE took other steps."""
    from aoc_cli.ope import evaluate_block as ope_eval
    from aoc_cli.store import targets_dir

    _root, store, _ = sepsis
    held = store.corpus("held")
    rows = np.arange(held.n_rows)

    def context():
        session = _session(store)
        session.model.meta["value"] = {"target": "fqe", "gamma": 1.0}
        return EvalContext.build(session, held, [])

    from aoc_cli.ope.fqe import default_steps

    steps = default_steps(held.n_rows, held.episode_starts, 1.0)
    settings = OPESettings(seed=3)
    fresh = np.linspace(0.0, 1.0, held.n_rows)
    ctx = context()
    got = ctx.targets(rows, {"settings": settings,
                             "behaviour_fqe": {"logged": fresh, "steps": steps}})
    np.testing.assert_array_equal(got, fresh)
    assert "behaviour's Q(o, a) by fitted Q evaluation" in ctx.target_source
    assert len(list(targets_dir(held.path).glob("fqe-behaviour-*.npy"))) == 1

    def never(*_a, **_k):
        raise AssertionError("fitted again")

    monkeypatch.setattr(ope_eval, "behaviour_fqe", never)
    np.testing.assert_array_equal(context().targets(rows, {"settings": settings}), fresh)

    alone = {}

    def fit_alone(*args, **_kwargs):
        alone["gamma"], alone["steps"] = args[5], args[6]
        return {"logged": np.full(held.n_rows, 0.5)}

    monkeypatch.setattr(ope_eval, "behaviour_fqe", fit_alone)
    other = OPESettings(seed=4, gamma=0.9)                    # the OPE's discount, not 1
    got = context().targets(rows, {"settings": other,
                                   "behaviour_fqe": {"logged": fresh, "steps": steps}})
    assert alone == {"gamma": 1.0, "steps": steps} and np.all(got == 0.5)
    alone.clear()
    quick = OPESettings(seed=5, fqe_steps=200)                # a quicker OPE: not the target
    got = context().targets(rows, {"settings": quick,
                                   "behaviour_fqe": {"logged": fresh, "steps": 200}})
    assert alone == {"gamma": 1.0, "steps": steps} and np.all(got == 0.5)


def test_fqe_off_on_the_logged_behaviour_is_a_warning_and_withheld(sepsis, monkeypatch):
    """The direct method values the logged behaviour beside the policies; outside the
    interval of the log's mean return, the OPE says so and withholds FQE's values."""
    from aoc_cli.ope import evaluate_block as ope_eval

    _root, store, _ = sepsis
    held = store.corpus("held")
    n = held.n_rows

    e = held.n_episodes
    counts = np.random.default_rng(0).multinomial(e, np.full(e, 1 / e), size=3)

    def fake(_log, _obs, _logged, policies, _settings, _progress=None, behaviour=False,
             propensity=None):
        recs = [{"q": np.zeros((n, held.n_actions)), "replicates": np.array([0.1, 0.2, 0.3]),
                 "counts": counts, "estimate": 0.2, "low": 0.0, "high": 0.4,
                 "fit_estimate": 0.2, "steps": 10, "refit_steps": 2} for _ in policies]
        return recs + [{"q": np.zeros((n, held.n_actions)), "logged": np.zeros(n),
                        "estimate": 5.0}] if behaviour else recs

    monkeypatch.setattr(ope_eval, "fqe_values", fake)
    out = ope_eval.off_policy_values(held, held.actions, {"aoc": held.actions},
                                     OPESettings(estimators=("pdwis", "fqe"), n_boot=50))
    fqe = out["policies"]["aoc"]["policy_value"]["fqe"]
    assert fqe["estimate"] is None and fqe["reason"].startswith(
        "FQE off on the logged behaviour (5, outside its mean return's 95% interval")
    assert out["behaviour_value"]["fqe"] == 5.0
    assert any(w.startswith("fqe values the logged behaviour at 5,") or
               w.startswith("fqe values the logged behaviour at 5 ")
               for w in out["ope_warnings"]), out["ope_warnings"]
    low, high = out["behaviour_value"]["low"], out["behaviour_value"]["high"]
    assert low <= out["behaviour_value"]["estimate"] <= high


def test_fqe_is_given_the_history_the_policies_decide_from(sepsis, monkeypatch):
    """With a history length, FQE's Q is a function of the observation and the last steps'
    observations and actions (the propensity model's features), as the policy's decision is."""
    from aoc_cli.ope import evaluate_block as ope_eval

    _root, store, _ = sepsis
    held = store.corpus("held")
    seen = {}

    def fake(_log, obs, _logged, policies, _settings, _progress=None, behaviour=False,
             propensity=None):
        seen["width"] = np.asarray(obs).shape[1]
        return [None] * len(policies)

    monkeypatch.setattr(ope_eval, "fqe_values", fake)
    d = held.observations.shape[1]
    for length, width in ((0, d), (2, d + 2 * (d + held.n_actions))):
        out = ope_eval.off_policy_values(held, held.actions, {"aoc": held.actions},
                                         OPESettings(estimators=("pdwis",), n_boot=20),
                                         history_length=length)
        assert seen["width"] == width
        assert out["ope"]["fqe_inputs"].startswith("the observation")
