"""The accountable controller (Algorithm 1 of the paper) and its decisions.

One step, top to bottom:

1. K candidate actions (uniform in a box, every action of a discrete space, or a black-box
   sampler such as behaviour cloning plus noise);
2. one batched belief pass, ``b_t = b(o_t, a, h_t)`` for every candidate, (K, d_b);
3. one batched decomposition against the corpus beliefs: corpus residual, minimal corpus
   subset and value estimate ``v_hat = sum_c w^c v^c`` for every candidate;
4. keep the candidates whose residual is within the epsilon-quantile of the K residuals
   (and, with ``residual_cap`` c, within c x the corpus's typical p90 residual; with
   ``min_support`` m, backed by at least m distinct episodes: aoc_cli/control/support.py);
5. the argmax of ``v_hat`` among them (ties: the smaller residual); with ``support_penalty``
   z, of ``v_hat - z sigma_v / sqrt(support)``.

In imitation mode (ABC) the belief is ``b(o_t, h_t)`` and the decision is the weighted action
of its minimal corpus subset: the weighted mean (continuous) or, discrete, the argmax of the
actions' scores, the subset's weighted sum of its rows' labels (aoc_cli.belief.row_labels).
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field

import numpy as np

from aoc_cli.belief.row_labels import default_row_smoothing, row_labels
from aoc_cli.control.config import ControllerConfig
from aoc_cli.index.search.neighbourhood import SETS, Neighbourhood, measured_cells
from aoc_cli.control.rule import action_bounds, candidate_actions
from aoc_cli.control.rule import choose as _choose
from aoc_cli.control.rule import reads_support, residual_cap
from aoc_cli.control.support import row_episodes, support_episodes
from aoc_cli.errors import AocError, ModelMissing, call, param
from aoc_cli.store import History
from aoc_cli.threads import one_thread


@dataclass(repr=False)
class Decision:
    """One decision and everything needed to audit it.

    ``action`` (d_a,) float or a scalar int (discrete); ``support_rows`` (m,) corpus rows of
    the minimal corpus subset, ``support_weights`` (m,), ``support_distances`` (m,) belief
    distances to the query. ``candidates`` (K, d_a) or (K,), with ``candidate_residuals``,
    ``candidate_values`` (K,) and ``passed`` (K,) bool (empty in imitation mode).
    ``support``: the effective number of distinct episodes behind the decision's value
    (:mod:`aoc_cli.control.support`), ``candidate_support`` (K,) each candidate's (computed
    where ``min_support`` or ``support_penalty`` reads it, else empty),
    ``support_counts`` (m,) the distinct episodes at each supporting row's belief.
    ``support_labels`` (m, n) each supporting row's label and ``scores`` (n,) the actions'
    scores (discrete imitation: :mod:`aoc_cli.belief.row_labels`; else empty).
    """

    action: np.ndarray
    value: float | None
    residual: float
    support_rows: np.ndarray
    support_weights: np.ndarray
    support_distances: np.ndarray
    candidates: np.ndarray
    candidate_residuals: np.ndarray
    candidate_values: np.ndarray
    passed: np.ndarray
    chosen: int
    threshold: float
    warnings: list[str] = field(default_factory=list)
    support: float = float("nan")
    candidate_support: np.ndarray = field(default_factory=lambda: np.empty(0))
    support_counts: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    support_labels: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    scores: np.ndarray = field(default_factory=lambda: np.empty(0))
    #: Rule 7 (do no harm): the clinicians' likely action was kept, no alternative's lower
    #: bound beating its value (aoc_cli.index.search.neighbourhood); None where the rule is off.
    kept: bool | None = None
    #: the observation's measured cells (d_o,) bool that rule 7 read; None: all
    measured: np.ndarray | None = None

    def __repr__(self) -> str:
        """One line: the action, v_hat, residual and supporting rows (never the candidates'
        arrays: ``.candidates`` holds them)."""
        action = np.asarray(self.action)
        shown = int(action) if action.ndim == 0 else np.round(action.astype(float), 4).tolist()
        value = "" if self.value is None else f", value={self.value:.4g}"
        rows = ", ".join(f"{int(r)}: {w:.2f}" for r, w in zip(self.support_rows[:6],
                                                              self.support_weights[:6]))
        more = ", ..." if len(self.support_rows) > 6 else ""
        return (f"Decision(action={shown}{value}, residual={self.residual:.4g}, "
                f"support=[{rows}{more}] ({len(self.support_rows)} rows), "
                f"candidates={len(self.candidates)}"
                + (f", warnings={len(self.warnings)}" if self.warnings else "") + ")")

    def to_frame(self):
        """The minimal corpus subset, one row per supporting row: row, weight, distance,
        and the distinct episodes at its belief (pandas, imported only here)."""
        import pandas as pd  # a notebook's library

        m = len(self.support_rows)
        counts = self.support_counts if len(self.support_counts) == m else np.full(m, np.nan)
        return pd.DataFrame({"row": np.asarray(self.support_rows, np.int64),
                             "weight": self.support_weights,
                             "distance": self.support_distances, "episodes_here": counts})

    def _repr_html_(self) -> str:
        rows = "".join(f"<tr><td>{int(r)}</td><td>{w:.1%}</td><td>{d:.4g}</td></tr>"
                       for r, w, d in zip(self.support_rows, self.support_weights,
                                          self.support_distances))
        warn = "".join(f"<p>warning: {html.escape(w)}</p>" for w in self.warnings)
        return (f"<p><b>{html.escape(repr(self))}</b></p>{warn}<table><tr><th>row</th>"
                f"<th>weight</th><th>distance</th></tr>{rows}</table>")


class Controller:
    """AOC (value mode) or ABC (imitation mode) over one corpus, model and index.

    ``index`` is a :class:`aoc_cli.index.CorpusIndex` (beliefs of every corpus row,
    values, the nearest-neighbour index); ``selection`` an optional (N,) bool row mask applied
    at query time, with no rebuild.
    """

    def __init__(self, corpus, index, config: ControllerConfig | None = None,
                 selection: np.ndarray | None = None, bc_model=None, seed: int = 0,
                 action_space: dict | None = None):
        self.corpus = corpus
        self.index = index
        self.model = index.model
        self.config = config or ControllerConfig()
        self.selection = selection
        self.bc_model = bc_model
        self.rng = np.random.default_rng(seed)
        self.discrete = corpus.discrete
        self.action_space = action_space or corpus.action_space
        if self.config.sampler == "bc" and bc_model is None and self.model.mode == "value":
            raise ModelMissing(corpus.name, self.config.bc_model, mode="imitation",
                               why=f"{param('sampler', 'bc')} needs an imitation-mode model")
        self.corpus_actions = corpus.actions
        if not self.discrete:
            self.low, self.high = action_bounds(self.action_space, self.corpus_actions)
            self.span = np.maximum(self.high - self.low, 1e-12)
        values = index.values
        self.value_std = float(np.std(values)) if values is not None and len(values) else 1.0
        self.row_episode = row_episodes(corpus.episode_starts)
        self._neighbourhood = None

    @property
    def k(self) -> int:
        """Neighbours per query: ``config.k`` when set (``--k``), else the k the index was
        built with (the k rule, :mod:`aoc_cli.decompose.k_rule`)."""
        return int(self.config.k) if self.config.k is not None else int(self.index.k)

    @property
    def row_smoothing(self) -> float:
        """lambda of the rows' labels (discrete imitation): ``config.row_smoothing`` when set,
        else :func:`aoc_cli.belief.row_labels.default_row_smoothing` for the index's
        candidates."""
        if self.config.row_smoothing is not None:
            return float(self.config.row_smoothing)
        return default_row_smoothing(self.discrete, self.index.candidates)

    # -- candidates ------------------------------------------------------------------------
    def sample_candidates(self, observation: np.ndarray, history: History) -> np.ndarray:
        """(K, d_a) float candidates, or (n,) int: every action of a discrete space."""
        if self.discrete:
            return candidate_actions(self.rng, 0, n_actions=self.corpus.n_actions)
        k = self.config.candidates
        if self.config.sampler == "uniform":
            return candidate_actions(self.rng, k, self.low, self.high)
        # bc: the behaviour-cloning action plus Gaussian noise (the first candidate noiseless)
        mean = np.asarray(self.bc_model.predict(observation[None], None, history))[0]
        noise = self.rng.standard_normal((k, len(self.low))) * self.config.bc_noise * self.span
        noise[0] = 0.0
        return np.clip(mean[None, :] + noise, self.low, self.high)

    # -- rule 7: do no harm ---------------------------------------------------------------
    @property
    def do_no_harm(self) -> bool:
        """Whether rule 7 decides: value mode, discrete actions, and ``do_no_harm`` on, or
        None where rule 2's exact-repeat bound (a ``support_penalty``) does not rank."""
        if not (self.discrete and self.model.mode == "value" and self.index.values is not None):
            return False
        if self.config.do_no_harm is None:
            return not reads_support(self.config)
        return self.config.do_no_harm == "on"

    @property
    def neighbourhood(self) -> Neighbourhood:
        """The log's rows near an observation, valued by rule 7's values, else the index's."""
        if self._neighbourhood is None:
            saved = getattr(self.model, "neighbourhood_values", None)
            made = self.model.meta.get("neighbourhood") or {}
            measured = measured_cells(self.corpus)     # the cells not filled at ingest
            old = ("over every cell, from before its neighbourhoods left the filled cells out"
                   if measured is not None and made.get("distance") != "measured cells" else
                   "over the 100 nearest rows, from before its denoised sets"
                   if made.get("sets") != SETS else None)
            if saved is not None and old is not None:
                raise AocError(f"model {self.model.id!r} holds rule 7's values {old}: retrain "
                               f"it ({call('train', self.corpus.name, overwrite=True)})")
            space = None if saved is None else getattr(self.model, "neighbourhood_space", None)
            self._neighbourhood = Neighbourhood(
                self.corpus.observations, self.corpus_actions, self.row_episode,
                self.corpus.n_actions, values=self.index.values if saved is None else saved,
                measured=measured, space=space)
        return self._neighbourhood

    def harm_inputs(self, observations: np.ndarray, value: np.ndarray,
                    support: np.ndarray | None, measured: np.ndarray | None = None
                    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Rule 7's (lower (S, K), kept (S,)) at observations (S, d_o), v_hat ``value``
        (S, K) of the discrete actions, ``measured`` (S, d_o) bool their measured cells (None:
        all); (None, None) where it is off. Rule 2's bound stays the key where it ranks;
        elsewhere each action's bound over the neighbourhood."""
        if not self.do_no_harm:
            return None, None
        near = self.neighbourhood.at(observations, measured)
        lower = None
        if not reads_support(self.config):
            lower = self.neighbourhood.bounds(near)[:, :value.shape[1]]
        return lower, near.likely

    # -- one step --------------------------------------------------------------------------
    def decide(self, observation: np.ndarray, history: History,
               candidates: np.ndarray | None = None,
               selection: np.ndarray | None = None,
               measured: np.ndarray | None = None) -> Decision:
        """Decide at one step; ``history`` is a one-row History (1, L, ...). ``selection``:
        an (N,) bool row mask for this decision instead of the controller's own; ``measured``
        (d_o,) bool the observation's measured cells (None: all; rule 7 reads them on a log
        with gaps). Runs with one thread in torch, FAISS and BLAS
        (:func:`aoc_cli.threads.one_thread`)."""
        observation = np.asarray(observation, dtype=np.float32).reshape(-1)
        with one_thread():
            if self.model.mode == "imitation":
                return self._imitate(observation, history, selection)
            if candidates is None:
                candidates = self.sample_candidates(observation, history)
            return self.decompose_candidates(observation, history, candidates, choose=True,
                                             selection=selection, measured=measured)

    def decompose_candidates(self, observation: np.ndarray, history: History,
                             candidates: np.ndarray, choose: bool = True,
                             selection: np.ndarray | None = None,
                             measured: np.ndarray | None = None) -> Decision:
        """Decompose every candidate; with ``choose``, the decision rule (the epsilon filter
        and the argmax: :func:`aoc_cli.control.rule.choose`).

        Without ``choose`` the first candidate is reported (used to explain a given action).
        ``selection``, ``measured``: as in :meth:`decide`.
        """
        n = len(candidates)
        # one observation and one history broadcast to the n candidates (the GRU runs once)
        with one_thread():
            beliefs = self.model.beliefs(observation[None, :], candidates, history)
            dec = self.index.decompose(beliefs, k=self.k, selection=self._rows(selection))
        residual = np.asarray(dec.residual, dtype=np.float64)
        value = np.asarray(dec.value, dtype=np.float64)
        # every candidate's support only where a rule reads it (a few ms for K = 100)
        support = self.support(dec)[0] if reads_support(self.config) else np.empty(0)
        kept = None
        if choose:  # steps 4 and 5: the decision rule (aoc_cli.control.rule.choose)
            lower, likely = self.harm_inputs(observation[None], value[None], support[None],
                                             None if measured is None else
                                             np.asarray(measured, bool).reshape(1, -1))
            threshold, passed, chosen = _choose(
                residual[None], value[None], self.config, cap=self.residual_cap,
                support=support[None], value_std=self.value_std, lower=lower, kept=likely)
            threshold, passed, chosen = float(threshold[0, 0]), passed[0], int(chosen[0])
            if likely is not None:
                kept = bool(chosen == int(likely[0]))
        else:
            threshold, passed, chosen = float("nan"), np.ones(n, bool), 0
        own, counts = self.support(dec, chosen)  # the decision's own, for its record
        decision = Decision(
            action=np.asarray(candidates[chosen]),
            value=float(value[chosen]),
            residual=float(residual[chosen]),
            support_rows=_trim(dec.rows[chosen], dec.rows[chosen]),
            support_weights=_trim(dec.weights[chosen], dec.rows[chosen]),
            support_distances=_trim(dec.distance[chosen], dec.rows[chosen]),
            candidates=np.asarray(candidates),
            candidate_residuals=residual,
            candidate_values=value,
            passed=passed,
            chosen=chosen,
            threshold=threshold,
            support=float(own[0]),
            candidate_support=support,
            support_counts=_trim(counts[0], dec.rows[chosen]),
            kept=kept,
            measured=None if measured is None else np.asarray(measured, bool).reshape(-1),
        )
        decision.warnings = self.heterogeneity(decision)
        return decision

    def support(self, dec, which: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(Q,) the effective number of distinct episodes behind each of ``dec``'s values and
        (Q, m) the episodes at each vertex (:func:`aoc_cli.control.support.support_episodes`);
        ``which``: of that query alone, (1,) and (1, m)."""
        part = slice(None) if which is None else slice(which, which + 1)
        return support_episodes(self.index.beliefs, dec.rows[part], dec.weights[part],
                                dec.neighbours[part], self.row_episode)

    @property
    def residual_cap(self) -> float | None:
        """c x the index's typical p90 residual, or None (no cap set, or none recorded)."""
        return residual_cap(self.config.residual_cap, self.index.typical.p90)

    def _rows(self, selection: np.ndarray | None) -> np.ndarray | None:
        """The row mask of one decision: the one given, else the controller's own."""
        return self.selection if selection is None else selection

    def _imitate(self, observation: np.ndarray, history: History,
                 selection: np.ndarray | None = None) -> Decision:
        belief = self.model.beliefs(observation[None], None, history)
        dec = self.index.decompose(belief, k=self.k, selection=self._rows(selection))
        rows = _trim(dec.rows[0], dec.rows[0])
        weights = _trim(dec.weights[0], dec.rows[0])
        actions = self.corpus_actions[rows]
        labels, totals = np.empty((0, 0)), np.empty(0)
        if self.discrete:
            n = int(self.corpus.n_actions)
            lam = self.row_smoothing
            labels = row_labels(actions, self.index.beliefs[rows] if lam else None,
                                self.model.head_weights if lam else None, n, lam)
            totals = weights @ labels  # the actions' scores: sum_c w^c l^c over the rows
            action = np.asarray(int(np.argmax(totals)))
        else:
            action = (weights[:, None] * actions).sum(axis=0)
        value = None if dec.value is None else float(dec.value[0])
        support, counts = self.support(dec)
        decision = Decision(
            action=action, value=value, residual=float(dec.residual[0]),
            support_rows=rows, support_weights=weights,
            support_distances=_trim(dec.distance[0], dec.rows[0]),
            candidates=np.empty((0,)), candidate_residuals=np.empty(0),
            candidate_values=np.empty(0), passed=np.empty(0, bool), chosen=-1,
            threshold=float("nan"), support=float(support[0]),
            support_counts=_trim(counts[0], dec.rows[0]), support_labels=labels,
            scores=totals,
        )
        decision.warnings = self.heterogeneity(decision)
        return decision

    # -- warnings --------------------------------------------------------------------------
    def heterogeneity(self, d: Decision) -> list[str]:
        """Warnings when the supporting rows disagree (the paper's risky-decision signal); the
        rule is :func:`support_disagreement`'s, this adds the words."""
        acts_flag, values_flag = support_disagreement(
            d.support_rows[None], d.support_weights[None], self.corpus_actions,
            self.index.values, self.config, discrete=self.discrete,
            span=None if self.discrete else self.span, value_std=self.value_std)
        rows = d.support_rows[d.support_weights >= self.config.min_weight]
        out = []
        if acts_flag[0]:
            actions = self.corpus_actions[rows]
            if self.discrete:
                out.append(f"supporting rows disagree on the action: {sorted(set(actions.tolist()))}")
            else:
                spread = float(np.max((actions.max(0) - actions.min(0)) / self.span))
                out.append(f"supporting actions spread over {spread:.0%} of the action range")
        if values_flag[0]:
            v = self.index.values[rows]
            out.append(f"supporting values range from {v.min():.4g} to {v.max():.4g}")
        return out


def support_disagreement(rows: np.ndarray, weights: np.ndarray, corpus_actions: np.ndarray,
                         values: np.ndarray | None, config: ControllerConfig, *, discrete: bool,
                         span: np.ndarray | None, value_std: float) -> tuple[np.ndarray, np.ndarray]:
    """Do the supporting rows of S decisions disagree? rows, weights (S, m), -1 padded; only
    rows with weight >= ``min_weight`` count, and at least two of them.

    Returns two (S,) bool arrays: the actions disagree (discrete: not all the same; continuous:
    spread over more than ``action_spread`` of the action range ``span`` (d_a,) in some
    dimension), and the values (N,) range over more than ``value_spread`` corpus value stds.
    """
    keep = (rows >= 0) & (weights >= config.min_weight)
    safe = np.maximum(rows, 0)
    many = keep.sum(1) >= 2
    acts = corpus_actions[safe]
    with np.errstate(invalid="ignore"):
        if discrete:
            big, small = np.iinfo(np.int64).max, np.iinfo(np.int64).min
            act = np.where(keep, acts, small).max(1) != np.where(keep, acts, big).min(1)
        else:
            hi = np.where(keep[..., None], acts, -np.inf).max(1)
            lo = np.where(keep[..., None], acts, np.inf).min(1)
            act = np.max((hi - lo) / span, axis=1) > config.action_spread
        val = np.zeros(len(rows), bool)
        if values is not None and value_std > 0:
            v = values[safe]
            spread = np.where(keep, v, -np.inf).max(1) - np.where(keep, v, np.inf).min(1)
            val = spread > config.value_spread * value_std
    return act & many, val & many


def _trim(values: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Drop the -1 padding of a decomposition row."""
    return np.asarray(values)[np.asarray(rows) >= 0]
