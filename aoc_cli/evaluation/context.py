"""What ``aoc evaluate`` prepares once before scoring chunks of episodes: the checked inputs,
the arrays every chunk reads, the candidates of value mode and the kNN baseline."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.belief.config import REWARD_TARGETS
from aoc_cli.belief.targets import held_out_targets, value_spec
from aoc_cli.control.controller import support_disagreement
from aoc_cli.control.rule import action_bounds
from aoc_cli.control.episodes import check_same_spaces
from aoc_cli.decompose import subset_size
from aoc_cli.errors import AocError, NoRewards, call
from aoc_cli.index.search import BatchSearch, BeliefIndex
from aoc_cli.index.search.strata import candidate_search
from aoc_cli.ope.evaluate_block import behaviour_targets
from aoc_cli.settings import SMALL_LOG_ROWS

#: The baselines ``aoc evaluate`` scores on the same steps (``--baselines``).
BASELINES = ("knn", "bc")


def check_inputs(corpus, data, mode: str, baselines, value_target: str | None) -> list[str]:
    """Refuse held-out data the model cannot score; return the baselines as a list."""
    if mode == "value" and value_target in REWARD_TARGETS and not data.has_rewards:
        raise NoRewards(data.name, "a value-mode model",
                        f"corpus {data.name!r} has no rewards: a value-mode model (target "
                        f"{value_target!r}) cannot be scored on it; evaluate an imitation-mode "
                        f"model ({call('train', mode='imitation')}) or one trained on a column")

    check_same_spaces(corpus, data, "evaluate it")
    if data.n_rows == 0 or data.n_episodes == 0:
        raise AocError(f"corpus {data.name!r} holds no steps to evaluate")
    names = [b.strip() for b in (baselines or []) if b.strip()]
    unknown = [b for b in names if b not in BASELINES and b != "none"]
    if unknown:
        raise AocError(f"unknown baseline {unknown[0]!r}: use {', '.join(BASELINES)} "
                       "(comma-separated) or none")
    return [b for b in names if b != "none"]


def episode_rows(starts: np.ndarray, episodes: np.ndarray) -> np.ndarray:
    """(R,) the rows of ``episodes`` in order, from episode offsets (E + 1,)."""
    lo, hi = starts[episodes], starts[episodes + 1]
    lengths = hi - lo
    offsets = np.repeat(lo - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
    return np.arange(int(lengths.sum()), dtype=np.int64) + offsets


def heterogeneity(ctx: "EvalContext", rows: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(S,) bool: the supporting rows (S, m) disagree, by the controller's own rule
    (:func:`aoc_cli.control.controller.support_disagreement`)."""
    acts, values = support_disagreement(
        rows, weights, ctx.corpus_actions, ctx.index.values, ctx.config, discrete=ctx.discrete,
        span=None if ctx.discrete else ctx.span, value_std=ctx.value_std)
    return acts | values


def candidate_beliefs(model, obs: np.ndarray, hist, cands: np.ndarray,
                      batch: int = 65536) -> np.ndarray:
    """(S * K, d_b) value-mode beliefs b(o, a, h) of K candidates (S, K) or (S, K, d_a) at S
    steps; each step's history goes through the GRU once and is shared by its candidates."""
    import torch

    s, kk = cands.shape[:2]
    enc, net, L = model.encoder, model.net, model.history_length
    out = np.empty((s * kk, model.d_b), np.float32)
    per = max(1, batch // kk)
    with torch.no_grad():
        for i in range(0, s, per):
            sl = slice(i, min(s, i + per))
            n = sl.stop - sl.start
            memory = None
            if L > 0:
                steps = enc.steps(*[np.asarray(x)[sl, -L:] for x in hist])
                memory = net.memory(steps).repeat_interleave(kk, dim=0)
            o = enc.observations(obs[sl]).repeat_interleave(kk, dim=0)
            c = cands[sl].reshape(n * kk, *cands.shape[2:])
            a = enc.actions(c)
            out[sl.start * kk:sl.stop * kk] = net.belief_from_memory(memory, o, a).numpy()
    return out


#: Above this many corpus rows, evaluate searches an IVF structure built for the run
#: (:data:`aoc_cli.settings.SMALL_LOG_ROWS`).
EXACT_MAX_ROWS = SMALL_LOG_ROWS


def _exact(vectors: np.ndarray):
    """An exact (flat) index over ``vectors``, rows numbered 0..n-1."""
    return BeliefIndex.build(np.ascontiguousarray(vectors, dtype=np.float32), kind="flat")


def search_structure(index, vectors, exact: bool | None, seed: int = 0):
    """The session's own (exact) index, or a :class:`BatchSearch` for a large corpus."""
    if exact or (exact is None and len(vectors) <= EXACT_MAX_ROWS):
        return index
    return BatchSearch(vectors, seed=seed)


class KNNBaseline:
    """The k nearest corpus rows on standardised inputs (imitation: the observation; value:
    the observation and the encoded action; exact search up to EXACT_MAX_ROWS rows, IVF
    beyond), k = d_b + 1 (:func:`aoc_cli.decompose.subset_size`: as many rows as ABC's subset
    may use; not the index's k). Imitation: the neighbours'
    action shares (discrete) or mean action; value: their mean value for the logged action,
    and for discrete actions the best of the actions."""

    def __init__(self, ctx: "EvalContext"):
        self.k = subset_size(ctx.model.d_b)
        self.extra = ctx.max_episode_length if ctx.own else 0
        obs = np.asarray(ctx.corpus.observations, np.float64)
        self.mean, self.std = obs.mean(0), np.where(obs.std(0) > 1e-9, obs.std(0), 1.0)
        self.value = ctx.mode == "value"
        x = self.features(ctx, obs, ctx.corpus_actions)
        # exact (flat: a batch is searched cell by cell, aoc_cli/index/search/cells.py), or IVF when large
        x = x.astype(np.float32)
        self.nn = search_structure(None, x, ctx.exact, ctx.seed) or \
            BeliefIndex.build(x, kind="flat")
        self.wide = min(self.k + self.extra, len(x))

    def features(self, ctx, obs, actions) -> np.ndarray:
        z = (np.asarray(obs, np.float64) - self.mean) / self.std
        if not self.value:
            return z
        if ctx.discrete:
            return np.concatenate([z, np.eye(ctx.n_actions)[np.asarray(actions)]], axis=1)
        a = (np.asarray(actions, np.float64) - ctx.low) / ctx.span
        return np.concatenate([z, a.reshape(len(z), -1)], axis=1)

    def neighbours(self, ctx, x: np.ndarray, query_episodes: np.ndarray) -> np.ndarray:
        """(S, k) corpus rows nearest to features (S, F), own episode left out when own."""
        _, idx = self.nn.search(x.astype(np.float32), self.wide)
        if not self.extra:
            return idx[:, :self.k]
        keep = ctx.corpus_episode[idx] != query_episodes[:, None]
        order = np.argsort(~keep, axis=1, kind="stable")[:, :self.k]
        return np.take_along_axis(idx, order, axis=1)

    def predict(self, ctx, obs, logged, query_episodes) -> dict:
        idx = self.neighbours(ctx, self.features(ctx, obs, logged), query_episodes)
        if not self.value:
            acts = ctx.corpus_actions[idx]
            if ctx.discrete:
                shares = np.stack([(acts == a).mean(1) for a in range(ctx.n_actions)], axis=1)
                return {"decided": shares.argmax(1), "scores": shares}
            return {"decided": acts.mean(1)}
        out = {"v_hat": ctx.index.values[idx].mean(1), "decided": None}
        if ctx.discrete:
            out["decided"] = self.action_values(ctx, obs, query_episodes).argmax(1)
        return out

    def action_values(self, ctx, obs, query_episodes) -> np.ndarray:
        """(S, n) value mode, discrete actions: the neighbours' mean value of each action."""
        per = [ctx.index.values[self.neighbours(
            ctx, self.features(ctx, obs, np.full(len(obs), a)), query_episodes)].mean(1)
            for a in range(ctx.n_actions)]
        return np.stack(per, axis=1)


@dataclass
class EvalContext:
    """Everything the chunks of one evaluation share (read-only)."""

    session: object
    data: object
    own: bool
    baselines: list
    seed: int
    exact: bool | None = None
    selection: np.ndarray | None = None

    @classmethod
    def build(cls, session, data, baselines, seed: int = 0,
              exact: bool | None = None,
              selection: np.ndarray | None = None) -> "EvalContext":
        model = session.model
        value_target = (model.meta.get("value") or {}).get("target")
        names = check_inputs(session.corpus, data, model.mode, baselines, value_target)
        ctx = cls(session, data, data.hash == session.corpus.hash, names, int(seed), exact,
                  selection)
        ctx._prepare()
        return ctx

    def _prepare(self) -> None:
        corpus, data, model = self.corpus, self.data, self.model
        self.mode = model.mode
        self.config = self.session.controller.config
        self.index = self.session.index
        self.search = search_structure(self.index.index, self.index.beliefs, self.exact,
                                       self.seed)
        # step 1 as the index takes its candidates (aoc_cli.index.search.strata), prepared once;
        # per action with the run's IVF structure: one search per action (IVF above
        # EXACT_MAX_ROWS rows of the action, else exact)
        split = None
        if isinstance(self.search, BatchSearch):
            def split(rows, beliefs=self.index.beliefs, seed=self.seed):
                vectors = np.take(beliefs, rows, axis=0)
                return search_structure(None, vectors, None, seed) or _exact(vectors)
        self.step1 = candidate_search(self.search, self.index.candidates, self.index.strata,
                                      split)
        self.history_length = model.history_length
        self.k = self.session.controller.k
        self.discrete, self.n_actions = corpus.discrete, corpus.n_actions
        self.corpus_actions = np.asarray(corpus.actions)
        self.corpus_episode = corpus.episode_of(np.arange(corpus.n_rows))
        self.max_episode_length = int(np.diff(corpus.episode_starts).max())
        self.data_starts = np.asarray(data.episode_starts, np.int64)
        self.data_obs = np.asarray(data.observations)
        self.data_actions = np.asarray(data.actions)
        self.head = model.head_weights
        self.row_smoothing = self.session.controller.row_smoothing  # discrete imitation
        if self.discrete:
            self.majority = int(np.bincount(self.corpus_actions, minlength=self.n_actions).argmax())
        else:
            self.low, self.high = action_bounds(corpus.action_space, self.corpus_actions)
            self.span = np.maximum(self.high - self.low, 1e-12)
        values = self.index.values
        self.value_std = float(np.std(values)) if values is not None and len(values) else 1.0
        self._data_values = None
        self.target_source = None
        self.knn = KNNBaseline(self) if "knn" in self.baselines else None

    def targets(self, rows: np.ndarray, ope: dict | None = None) -> np.ndarray | None:
        """(S,) float64 the value target of held-out ``rows`` (value mode; None in imitation
        mode): the model's own values when the data are its corpus, else the target computed
        on the held-out log as the model's values were. For ``fqe`` values, the logged
        behaviour's Q(o, a) by fitted Q evaluation of the held-out log
        (:func:`aoc_cli.ope.evaluate_block.behaviour_targets`: the OPE's own when ``ope``, its
        block, fitted it at the model's discount and FQE's default steps and schedule; else
        fitted alone at those: an OPE made quicker does not change the target; kept beside
        the log), or where that cannot
        run by aoc's own, as the model's values were
        (:func:`aoc_cli.belief.targets.held_out_targets`, kept too). Computed on first use:
        only the driver reads them (the chunks' decisions do not need them: a Ray task never
        computes them)."""
        if self.mode != "value":
            return None
        if self._data_values is None:
            model = self.model
            if self.own:
                self._data_values = np.asarray(model.values, np.float64)
                self.target_source = "the model's own values (the data are its corpus)"
            else:
                spec = model.meta.get("value") or {}
                value, gamma = spec.get("target", "return"), float(spec.get("gamma", 0.99))
                v = None
                if value == "fqe":
                    seed = ope["settings"].seed if ope else self.seed
                    v = behaviour_targets(self.data, gamma, seed, ope)
                if v is None:
                    v = held_out_targets(self.data, value, gamma)
                    self.target_source = value_spec(value, gamma)["definition"] + \
                        " (the held-out log's)"
                else:
                    self.target_source = (
                        "the logged behaviour's Q(o, a) by fitted Q evaluation of the "
                        f"held-out log (SARSA, gamma {gamma:g}): another estimator of what the "
                        "model's values estimate")
                self._data_values = v
        return self._data_values[np.asarray(rows, np.int64)]

    @property
    def corpus(self):
        return self.session.corpus

    @property
    def model(self):
        return self.session.model

    def candidates(self, rows: np.ndarray) -> np.ndarray:
        """The controller's candidates at each of ``rows`` (S,): every action of a discrete
        space (S, n); K uniform actions in the box (S, K, d_a), seeded by the chunk's first
        row so a chunk gives the same candidates wherever it runs."""
        s = len(rows)
        if self.discrete:
            return np.broadcast_to(np.arange(self.n_actions), (s, self.n_actions)).copy()
        rng = np.random.default_rng([self.seed, int(rows[0]) if s else 0])
        kk = self.config.candidates
        return rng.uniform(self.low, self.high, size=(s, kk, len(self.low)))
