"""`aoc evaluate NAME --data HELD_OUT`: every logged step of a corpus decided in batches and
scored against what was logged.

For a chunk of whole episodes of the held-out corpus (S steps):

1. the logged observations (S, d_o) and histories (S, L, ...) of the held-out corpus;
2. one batched belief pass: imitation b(o, h) (S, d_b); value b(o, a, h) for the logged action
   (S, d_b) and for the controller's candidates (S * K, d_b), the GRU run once per step;
3. one batched decomposition against NAME's corpus beliefs. When the held-out corpus *is*
   NAME, each step's own episode is left out of its neighbours (as ``aoc explain --data`` does
   with its row mask; here per query: :class:`LeaveEpisodeOut`), so no step is explained by
   its own row;
4. the decision: imitation, the weighted action of the minimal corpus subset (discrete: the
   argmax of the actions' scores, the subset's weighted sum of its rows' labels,
   aoc_cli.belief.row_labels); value, the controller's one rule over the candidates
   (:func:`aoc_cli.control.rule.choose`, batched);
5. baselines on the same steps: ``knn`` (the k = d_b + 1 nearest corpus rows, standardised,
   own episode left out likewise) and ``bc`` (the model's own head, the black box ABC explains).

Independent chunks of episodes: :func:`score_episodes` scores one (a :class:`StepScores`),
:func:`merge` joins chunks in any grouping, :func:`conclude` adds the OPE and the summary;
:func:`score_log` runs them in one process (aoc_cli.evaluation.ray farms the chunks out).
"""

from __future__ import annotations

import time

import numpy as np

from aoc_cli import metrics as sc
from aoc_cli.belief.row_labels import subset_scores
from aoc_cli.control.rule import choose, reads_support, residual_cap
from aoc_cli.control.support import support_episodes
from aoc_cli.decompose import decompose
from aoc_cli.errors import AocError
from aoc_cli.evaluation.context import (
    BASELINES,
    EXACT_MAX_ROWS,
    EvalContext,
    candidate_beliefs,
    check_inputs,
    episode_rows,
    heterogeneity,
)
from aoc_cli.evaluation.step_scores import StepScores
from aoc_cli.index.search.neighbourhood import measured_cells
from aoc_cli.index.search.strata import PerAction
from aoc_cli.ope.evaluate_block import ope_block, put_ope, wanted
from aoc_cli.rows import distinct_rows
from aoc_cli.threads import one_thread

#: Held-out steps per chunk (whole episodes; a chunk has at least one episode).
CHUNK_STEPS = 4096


def merge(parts: list[StepScores]) -> StepScores:
    """Concatenate chunk results (in the given order) into one."""
    if not parts:
        raise AocError("no steps were scored")
    m = max(p.support_rows.shape[1] for p in parts)

    def pad(a, fill):
        return np.pad(a, ((0, 0), (0, m - a.shape[1])), constant_values=fill)

    def cat(name):
        vals = [getattr(p, name) for p in parts]
        return None if vals[0] is None else np.concatenate(vals)

    base = {}
    for name in parts[0].baselines:
        # a value-mode kNN of continuous actions decides nothing: its "decided" is None
        base[name] = {k: None if parts[0].baselines[name][k] is None
                      else np.concatenate([p.baselines[name][k] for p in parts])
                      for k in parts[0].baselines[name]}
    return StepScores(
        row=cat("row"), episode=cat("episode"), step=cat("step"), logged=cat("logged"),
        decided=cat("decided"), residual=cat("residual"), warning=cat("warning"),
        support_rows=np.concatenate([pad(p.support_rows, -1) for p in parts]),
        support_weights=np.concatenate([pad(p.support_weights, 0.0) for p in parts]),
        scores=cat("scores"), v_hat=cat("v_hat"), target=cat("target"), baselines=base,
        decided_value=cat("decided_value"))


def chunks(ctx: EvalContext, max_steps: int = CHUNK_STEPS) -> list[np.ndarray]:
    """The held-out episodes in consecutive groups of about ``max_steps`` steps."""
    lengths = np.diff(ctx.data_starts)
    out, cur, total = [], [], 0
    for e, n in enumerate(lengths):
        if cur and total + n > max_steps:
            out.append(np.asarray(cur))
            cur, total = [], 0
        cur.append(e)
        total += int(n)
    if cur:
        out.append(np.asarray(cur))
    return out


def chunk_size(ctx: EvalContext, chunk_steps: int = CHUNK_STEPS) -> int:
    """Held-out steps per chunk: ``chunk_steps``, or 16 times as many where each distinct
    observation and history is decided once (:func:`_value_distinct` batches those itself)."""
    distinct = ctx.mode == "value" and ctx.discrete and not ctx.own
    return chunk_steps * 16 if distinct else chunk_steps


# -- one chunk ---------------------------------------------------------------------------------

def score_episodes(ctx: EvalContext, episodes) -> StepScores:
    """Decide and score every step of held-out ``episodes`` (episode numbers of the data)."""
    rows = episode_rows(ctx.data_starts, np.asarray(episodes, dtype=np.int64))
    ep = np.searchsorted(ctx.data_starts, rows, side="right") - 1
    obs = ctx.data_obs[rows]
    hist = ctx.data.history(rows, ctx.history_length)
    logged = ctx.data_actions[rows]
    if ctx.mode == "imitation":
        out = _imitate(ctx, rows, ep, obs, hist, logged)
    elif ctx.discrete and not ctx.own:
        return _value_distinct(ctx, rows, ep, obs, hist, logged)
    else:
        out = _value(ctx, rows, ep, obs, hist, logged)
    if "knn" in ctx.baselines:
        out.baselines["knn"] = ctx.knn.predict(ctx, obs, logged, ep)
    return out


def _decompose(ctx: EvalContext, beliefs: np.ndarray, query_episodes: np.ndarray):
    # step 1's candidates as the index takes them (the k nearest rows, or those of each
    # action), of other episodes than the query's when the data are the corpus itself
    index = ctx.step1
    if ctx.own:
        def own_out(search, rows):
            episode = ctx.corpus_episode if rows is None else ctx.corpus_episode[rows]
            return LeaveEpisodeOut(search, episode, query_episodes, ctx.max_episode_length)

        index = index.wrapped(own_out) if isinstance(index, PerAction) else own_out(index, None)
    return decompose(ctx.index.beliefs, beliefs, k=ctx.k, values=ctx.index.values, index=index,
                     selection=ctx.selection)


def _imitate(ctx, rows, ep, obs, hist, logged) -> StepScores:
    model = ctx.model
    beliefs = model.beliefs(obs, None, hist)
    dec = _decompose(ctx, beliefs, ep)
    used = dec.rows >= 0
    acts = ctx.corpus_actions[np.maximum(dec.rows, 0)]
    head = beliefs.astype(np.float64) @ ctx.head.weight.T + ctx.head.bias
    scores = None
    if ctx.discrete:
        scores = subset_scores(dec.rows, dec.weights, ctx.corpus_actions, ctx.n_actions,
                               ctx.index.beliefs, ctx.head, ctx.row_smoothing)
        decided = scores.argmax(1)
        probs = np.exp(head - head.max(1, keepdims=True))
        probs /= probs.sum(1, keepdims=True)
        bc = {"decided": probs.argmax(1), "scores": probs}
    else:
        w = np.where(used, dec.weights, 0.0)
        decided = np.einsum("qm,qmd->qd", w, acts.reshape(len(rows), -1,
                                                          ctx.corpus_actions.shape[1]))
        bc = {"decided": head}
    out = StepScores(rows, ep, rows - ctx.data_starts[ep], logged, decided, dec.residual,
                     heterogeneity(ctx, dec.rows, dec.weights), dec.rows, dec.weights,
                     scores=scores)
    if "bc" in ctx.baselines:
        out.baselines["bc"] = bc
    return out


def _candidates_decided(ctx, rows, ep, obs, hist):
    """The controller's rule (:func:`aoc_cli.control.rule.choose`, as Controller.decompose_candidates's)
    over its candidates at S steps:
    (candidates (S, K[, d_a]), the decomposition of every candidate (S * K queries), values
    (S, K), the chosen candidate (S,), its query (S,), the bc head (S, K) or None)."""
    model, cfg = ctx.model, ctx.config
    s = len(rows)
    cands = ctx.candidates(rows)                                    # (S, K) or (S, K, d_a)
    kk = cands.shape[1]
    b_c = candidate_beliefs(model, obs, hist, cands)                # (S * K, d_b)
    dec = _decompose(ctx, b_c, np.repeat(ep, kk))
    res = dec.residual.reshape(s, kk)
    val = dec.value.reshape(s, kk)
    support = None
    if reads_support(cfg):  # the episodes behind each value (control/support.py)
        support = support_episodes(ctx.index.beliefs, dec.rows, dec.weights, dec.neighbours,
                                   ctx.corpus_episode)[0].reshape(s, kk)
    lower, likely = ctx.session.controller.harm_inputs(  # the held-out log's own gaps
        obs, val, support, measured_cells(ctx.data, rows))
    _thr, _passed, chosen = choose(res, val, cfg, support=support, value_std=ctx.value_std,
                                   cap=residual_cap(cfg.residual_cap, ctx.index.typical.p90),
                                   lower=lower, kept=likely)
    pick = np.arange(s) * kk + chosen
    head_c = None
    if "bc" in ctx.baselines:
        head_c = (b_c.astype(np.float64) @ ctx.head.weight.T + ctx.head.bias).reshape(s, kk)
    return cands, dec, val, chosen, pick, head_c


def _value(ctx, rows, ep, obs, hist, logged) -> StepScores:
    s = len(rows)
    # v_hat of the logged action, against the logged value target
    b_logged = ctx.model.beliefs(obs, logged, hist)
    dec_l = _decompose(ctx, b_logged, ep)
    cands, dec, _val, chosen, pick, head_c = _candidates_decided(ctx, rows, ep, obs, hist)
    decided = cands[np.arange(s), chosen]
    out = StepScores(rows, ep, rows - ctx.data_starts[ep], logged, decided,
                     dec.residual[pick], heterogeneity(ctx, dec.rows[pick], dec.weights[pick]),
                     dec.rows[pick], dec.weights[pick], v_hat=dec_l.value,
                     decided_value=dec.value[pick])
    if head_c is not None:
        head_l = b_logged.astype(np.float64) @ ctx.head.weight.T + ctx.head.bias
        out.baselines["bc"] = {"decided": cands[np.arange(s), head_c.argmax(1)],
                               "v_hat": head_l[:, 0]}
    return out


def distinct_inputs(obs: np.ndarray, hist) -> tuple[np.ndarray, np.ndarray]:
    """(first (U,), inverse (S,)): the steps whose observation and history (S rows) differ,
    and each step's one among them (``obs[first][inverse]`` is ``obs``)."""
    parts = [np.ascontiguousarray(obs, np.float64).reshape(len(obs), -1)]
    parts += [np.asarray(x, np.float64).reshape(len(obs), -1) for x in hist]
    return distinct_rows(np.concatenate(parts, axis=1))


def _value_distinct(ctx, rows, ep, obs, hist, logged) -> StepScores:
    """Value mode, discrete actions, held-out data other than the corpus: a decision depends
    on the step's observation and history alone, so each distinct one is decided once (in
    batches of :data:`CHUNK_STEPS`) and the steps take its results; every action is a
    candidate, so the logged action's v_hat (and the baselines') is that candidate's."""
    first, inverse = distinct_inputs(obs, hist)
    parts, vals, heads = [], [], []
    for lo in range(0, len(first), CHUNK_STEPS):
        sel = first[lo:lo + CHUNK_STEPS]
        h = type(hist)(*[np.asarray(x)[sel] for x in hist])
        _c, dec, val, chosen, pick, head_c = _candidates_decided(ctx, rows[sel], ep[sel],
                                                                 obs[sel], h)
        parts.append(StepScores(
            rows[sel], ep[sel], rows[sel] - ctx.data_starts[ep[sel]], logged[sel], chosen,
            dec.residual[pick], heterogeneity(ctx, dec.rows[pick], dec.weights[pick]),
            dec.rows[pick], dec.weights[pick], decided_value=dec.value[pick]))
        vals.append(val)                                            # (m, n)
        heads.append(head_c)
    u = merge(parts)                                                # per distinct input
    val = np.concatenate(vals)                                      # (U, n)
    out = StepScores(rows, ep, rows - ctx.data_starts[ep], logged, u.decided[inverse],
                     u.residual[inverse], u.warning[inverse], u.support_rows[inverse],
                     u.support_weights[inverse], v_hat=val[inverse, logged],
                     decided_value=u.decided_value[inverse])
    if "bc" in ctx.baselines:
        head = np.concatenate(heads)                                # (U, n)
        out.baselines["bc"] = {"decided": head.argmax(1)[inverse],
                               "v_hat": head[inverse, logged]}
    if "knn" in ctx.baselines:
        per = ctx.knn.action_values(ctx, obs[first], ep[first])     # (U, n)
        out.baselines["knn"] = {"v_hat": per[inverse, logged], "decided": per.argmax(1)[inverse]}
    return out



class LeaveEpisodeOut:
    """A BeliefIndex seen without each query's own episode: ``search`` asks the index for
    k + (the longest episode) neighbours and drops those of the query's episode, so the k
    nearest rows of *other* episodes remain (exact for a flat index). ``query_episodes`` (Q,)
    aligns with the queries of the one ``decompose`` call it serves."""

    def __init__(self, index, row_episode: np.ndarray, query_episodes: np.ndarray,
                 longest: int):
        self.index, self.row_episode = index, row_episode
        self.query_episodes = np.asarray(query_episodes)
        self.longest = int(longest)
        self.n_rows, self.dim = index.n_rows, index.dim

    def search(self, queries, k, selection=None):
        """The k nearest rows of other episodes (within ``selection``, an (N,) bool mask)."""
        wide = min(int(k) + self.longest, self.index.n_rows)
        dist, rows = self.index.search(queries, wide, selection)
        own = (rows >= 0) & (self.row_episode[np.maximum(rows, 0)]
                             == self.query_episodes[:, None])
        keep = ~own & (rows >= 0)
        # stable: the kept neighbours in their order, the rest pushed to the end as padding
        order = np.argsort(~keep, axis=1, kind="stable")[:, :k]
        d = np.take_along_axis(np.where(keep, dist, np.inf), order, axis=1)
        r = np.take_along_axis(np.where(keep, rows, -1), order, axis=1)
        return d, r


# -- the whole held-out corpus -----------------------------------------------------------------

def summarise(ctx: EvalContext, res: StepScores) -> dict:
    """The metrics of merged step results (see :mod:`aoc_cli.metrics`)."""
    out: dict = {"mode": ctx.mode, "corpus": ctx.corpus.name, "model": ctx.model.id,
                 "data": ctx.data.name, "own_episode_left_out": ctx.own,
                 "steps": int(len(res.row)), "episodes": int(len(np.unique(res.episode)))}
    base: dict = {}
    if ctx.mode == "imitation":
        if ctx.discrete:
            out.update(sc.classification(res.logged, res.decided, res.scores, ctx.majority))
            for name, b in res.baselines.items():
                base[name] = sc.classification(res.logged, b["decided"], b["scores"],
                                               ctx.majority, full=False)
        else:
            out.update(sc.regression(res.logged, res.decided))
            for name, b in res.baselines.items():
                base[name] = sc.regression(res.logged, b["decided"])
    else:
        out.update(sc.value_fit(res.target, res.v_hat))
        out["value_target"] = ctx.target_source
        out.update(sc.agreement(res.logged, res.decided, ctx.discrete))
        for name, b in res.baselines.items():
            rec = sc.value_fit(res.target, b["v_hat"])
            rec.update(sc.agreement(res.logged, b["decided"], ctx.discrete)
                       if b.get("decided") is not None else {"agreement": None,
                                                              "action_distance": None})
            base[name] = rec
    typical = ctx.index.typical_residual
    out["residual"] = sc.residual_summary(res.residual, typical)
    out["extrapolating_share"] = sc.extrapolating_share(res.residual, typical)
    out["heterogeneity_share"] = float(np.mean(res.warning))
    out["support_max"] = int((res.support_rows >= 0).sum(1).max())
    out["k"] = int(ctx.k)
    search = ctx.search.describe() if hasattr(ctx.search, "describe") \
        else f"the index ({ctx.index.index.kind}, exact)" if ctx.index.index.kind == "flat" \
        else f"the index ({ctx.index.index.kind})"
    out["search"] = ctx.step1.describe(search) if isinstance(ctx.step1, PerAction) else search
    out["candidates"] = ctx.index.candidates
    out["baselines"] = base
    return out


def score_log(session, data, baselines=BASELINES, seed: int = 0, progress=None,
             chunk_steps: int = CHUNK_STEPS, exact: bool | None = None,
             selection: np.ndarray | None = None, ope=None) -> tuple[dict, StepScores]:
    """Score every step of corpus ``data`` with ``session`` (its corpus, model, index and
    controller settings); ``progress(done_steps, total_steps)``. ``exact``: search the
    session's own index (True), an IVF structure built for the run (False), or the index up
    to :data:`EXACT_MAX_ROWS` corpus rows and IVF beyond (None). ``selection``: an (N,) bool
    mask of the corpus rows the decisions may use (None: every row; the baselines always use
    every row). ``ope``: :class:`aoc_cli.ope.evaluate_block.OPESettings` of the offline policy
    evaluation of the decisions (value mode; None: all estimators when the log allows it, see
    :func:`aoc_cli.ope.evaluate_block.wanted`). Returns (summary, steps).
    Runs with one thread in torch, FAISS and BLAS (:func:`aoc_cli.threads.one_thread`)."""
    started = time.perf_counter()
    with one_thread():
        ctx = EvalContext.build(session, data, baselines, seed, exact, selection)
        wanted(ope, ctx.mode, data)       # a log the OPE cannot use is refused before deciding
        parts, done = [], 0
        for group in chunks(ctx, chunk_size(ctx, chunk_steps)):
            part = score_episodes(ctx, group)
            parts.append(part)
            done += len(part.row)
            if progress is not None:
                progress(done, ctx.data.n_rows)
    return conclude(ctx, data, merge(parts), ope, seed, started)


def conclude(ctx: EvalContext, data, res: StepScores, ope, seed: int, started: float):
    """The decided steps' OPE, targets and summary, once, here (Ray too): (summary, res)."""
    decided = time.perf_counter()
    with one_thread():
        block = ope_block(ctx.mode, data, res, ope, seed, history_length=ctx.history_length)
    ope_seconds = time.perf_counter() - decided
    res.target = ctx.targets(res.row, block)  # value mode: the held-out log's targets, once
    summary = summarise(ctx, res)
    put_ope(summary, block)
    summary["ope_seconds"] = ope_seconds
    summary["seconds"] = time.perf_counter() - started
    summary["steps_per_second"] = summary["steps"] / max(summary["seconds"], 1e-9)
    return summary, res


__all__ = ["BASELINES", "EXACT_MAX_ROWS", "LeaveEpisodeOut", "check_inputs", "chunks", "conclude",
           "merge", "score_episodes", "score_log", "summarise"]
