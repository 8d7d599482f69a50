"""The controller chosen on held-out episodes of the user's own log (value mode, discrete
actions: rule 6 of :mod:`aoc_cli.training.evidence`), by a rule stated in advance
(docs/design.md, "Settings from the log's evidence"). With a finite state the log revisits
(rule 2) the candidates are :func:`candidates`; without one (rule 7, :data:`HARM`) rule 7's
controller and the paper's, "in that state" read in the held-out rows nearest the step
(:func:`~aoc_cli.index.search.neighbourhood.episodes_near`) and the paper's first screened at
:data:`SCREEN` steps (:func:`harm_candidates`).

``aoc train`` holds out the validation episodes (``val_fraction``, 20%) from the belief's fit
(they only stop it early). After training, at every step of those episodes, every action is
decomposed over the *training* rows' beliefs and values, with the k the model records; each
candidate controller of :func:`candidates` decides at every held-out step from those
decompositions (:func:`aoc_cli.control.rule.choose`: the same rule as the controller, its
residual cap scaled by the training rows' own typical p90 residual); each candidate's
decisions are valued by fitted Q evaluation on the held-out episodes
(:func:`aoc_cli.ope.fqe.fqe_policies`: :data:`aoc_cli.ope.fqe.REFITS` bootstrap refits over
the episodes, the 95% interval by Student's t). The rule:

    the candidate with the highest lower bound, its 95% interval's lower end less the share
    of its decisions the held-out log hardly holds (held out fewer than :data:`MIN_PAIRS`
    times in that state, ``rare``) times the range of the held-out returns: FQE's Q of such
    a pair is its network's extrapolation, so the bound counts those decisions as worth
    anything from the worst return to the best; of equal bounds the more conservative
    (earlier in :func:`candidates`). Two kinds of estimate are no estimate: one outside the
    held-out episodes' returns (FQE diverged: seen on icu-sepsis-terminate's 1k log), and
    one whose median decision the held-out log holds fewer than :data:`MIN_PAIRS` times
    (seen on icu-sepsis's 50k log, the cap alone 0.888 [0.852, 0.923] by FQE, 0.788
    exact). A candidate without an estimate is not chosen, and when rule 2's own candidate
    has none the log cannot weigh the others against it, so it is kept.

The selection changes only the controller's settings saved with the model; the held-out
episodes give it states and outcomes that neither the belief nor the decompositions hold.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from aoc_cli.belief.model import Encoder
from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.rule import choose, residual_cap
from aoc_cli.control.support import row_episodes, support_episodes
from aoc_cli.decompose import decompose
from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.neighbourhood import (Neighbourhood, episodes_near,
                                                measured_cells)
from aoc_cli.ope.evaluate_block import truncated
from aoc_cli.ope.fqe import REFITS, fqe_policies, student_quantile
from aoc_cli.rows import distinct_rows
from aoc_cli.threads import one_thread
from aoc_cli.training.evidence import STATE_CAP
from aoc_cli.training.record import Recording

#: Training rows sampled for their typical residual (leave-those-rows-out), as the index does.
TYPICAL_SAMPLE = 500
#: FQE's gradient steps (None: :func:`aoc_cli.ope.fqe.default_steps`, from the held-out
#: episodes' horizon) and bootstrap refits.
FQE_STEPS, FQE_REFITS = None, REFITS
#: Held-out steps x actions whose beliefs are computed, distinct beliefs decomposed, at once.
BLOCK, QUERIES = 65536, 16384
#: Rule 7's premise: the held-out steps at which the paper's controller is first decided (its
#: median decision's count read there; every action decomposed at each step).
SCREEN = 500
#: The held-out transitions of a (state, action) pair below which FQE's Q of it is the
#: network's extrapolation: a candidate whose median decision has fewer is not valued.
MIN_PAIRS = 3
RULE = ("the highest lower bound of the 95% interval of FQE on the held-out episodes, less "
        "the returns' range times the share of decisions the held-out episodes took fewer "
        f"than {MIN_PAIRS} times in that state; of equal bounds the more conservative; an "
        "estimate outside the episodes' returns, or of a candidate whose median decision the "
        f"held-out episodes took fewer than {MIN_PAIRS} times in that state, is none (rule "
        "2's kept when it has none)")


#: How rule 7's premise reads the rule: "in that state" and the candidate kept.
NEAR = ("; without a finite state, \"in that state\" is among the held-out rows near the "
        "step (rule 7's sets), counted in episodes, and rule 7's is kept when it has none")


def candidates(penalty: float | None, cap: float = STATE_CAP) -> tuple[dict, ...]:
    """The candidate controllers, the most conservative first (the ties' order): rule 2's (an
    action trusted only where the log took it in that state, ranked by the lower bound of its
    value: ``penalty`` the support penalty rule 2 measured, :func:`aoc_cli.training.evidence.
    state_penalty`), each of its two parts alone, and the paper's. ``penalty`` None (the log
    gave no noise to bound): the cap and the paper's."""
    bounded = () if penalty is None else (
        {"residual_cap": cap, "support_penalty": float(penalty)},
        {"residual_cap": None, "support_penalty": float(penalty)})
    return bounded + ({"residual_cap": cap, "support_penalty": None},
                      {"residual_cap": None, "support_penalty": None})


#: Rule 7's premise (no finite state): rule 7's controller, then the paper's.
HARM = ({"do_no_harm": "on"}, {"do_no_harm": "off"})


def harm_decisions(corpus, data, rows: np.ndarray) -> np.ndarray:
    """(R,) rule 7's action at the held-out steps ``rows``: the same rule as the controller
    (:func:`choose` with the neighbourhood's bounds and likely action), its neighbourhoods
    the *training* rows' (never the step's own episode), each row valued by rule 7's values
    (``data.neighbourhood``, else the belief's targets)."""
    train = np.asarray(data.train_rows, np.int64)
    values = data.neighbourhood if data.neighbourhood is not None else data.values
    hood = Neighbourhood(np.asarray(corpus.observations)[train],
                         np.asarray(corpus.actions, np.int64)[train],
                         row_episodes(corpus.episode_starts)[train], int(corpus.n_actions),
                         values=np.asarray(values, np.float64)[train],
                         measured=measured_cells(corpus, train))
    near = hood.at(np.asarray(corpus.observations)[rows], measured_cells(corpus, rows))
    lower = hood.bounds(near)
    zeros = np.zeros_like(lower)
    return choose(zeros, zeros, ControllerConfig(do_no_harm="on"), lower=lower,
                  kept=near.likely)[2].astype(np.int64)


def harm_candidates(net, inputs, data, norm, corpus, config, k: int, rows, starts,
                    controllers) -> tuple[list, list, list]:
    """Rule 7's premise: (chosen, held, screened) per candidate of :data:`HARM`: its action
    (R,) at every held-out step, the held-out count of each
    (:func:`~aoc_cli.index.search.neighbourhood.episodes_near`), and None;
    the paper's is first decided at :data:`SCREEN` held-out steps drawn at random (every
    action decomposed: its cost), and where its median decision there is held fewer than
    :data:`MIN_PAIRS` times it is not fitted (chosen None, held the sample's counts,
    screened the sample's size): the rule gives it no estimate whatever FQE says."""
    obs = np.asarray(corpus.observations)[rows]
    logged = np.asarray(corpus.actions, np.int64)[rows]
    counts = episodes_near(obs, logged, starts, int(corpus.n_actions),
                           measured_cells(corpus, rows))
    chosen, held, screened = [], [], []
    for c in controllers:
        at = np.arange(len(rows))
        if c.get("do_no_harm") == "on":
            act = harm_decisions(corpus, data, rows)
        else:
            at = np.sort(np.random.default_rng(config.seed).choice(
                len(rows), size=min(SCREEN, len(rows)), replace=False))
            parts = decompositions(net, inputs, data, norm, corpus, k, config.seed,
                                   rows=rows[at])
            act = decisions(parts, (c,))[0]
            if np.median(counts[at, act]) >= MIN_PAIRS and len(at) < len(rows):
                at = np.arange(len(rows))
                act = decisions(decompositions(net, inputs, data, norm, corpus, k,
                                               config.seed), (c,))[0]
        full = len(at) == len(rows)
        chosen.append(act if full else None)
        held.append(counts[at, act])
        screened.append(None if full else len(at))
    return chosen, held, screened


def held_out_steps(corpus, data) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows (R,), starts (E_v + 1,), truncated (E_v,)) of the validation episodes, in the
    order of ``data.val_rows``."""
    starts = np.asarray(corpus.episode_starts, np.int64)
    eps = np.asarray(data.val_episodes, np.int64)
    lengths = starts[eps + 1] - starts[eps]
    rows = np.asarray(data.val_rows, np.int64)
    return rows, np.concatenate([[0], np.cumsum(lengths)]), truncated(corpus)[eps]


def decompositions(net, inputs, data, norm, corpus, k: int, seed: int = 0,
                   rows: np.ndarray | None = None) -> dict:
    """Every action at every held-out step (or at the corpus rows ``rows`` (R,)) decomposed
    over the training rows: residual, value, support (R, n), sigma_v, the training rows'
    typical p90 residual, and how many distinct beliefs were decomposed."""
    device = inputs.obs.device
    n = int(corpus.n_actions)
    encoder = Encoder(norm, True, n, device)
    tr = torch.as_tensor(data.train_rows, device=device)
    if rows is None:
        rows, _, _ = held_out_steps(corpus, data)
    with torch.no_grad():
        b_tr = torch.cat([net(*inputs.batch(tr[i:i + BLOCK]))[0]
                          for i in range(0, len(tr), BLOCK)]).cpu().numpy()
        per = max(1, BLOCK // n)
        out = []
        for i in range(0, len(rows), per):
            obs, _act, steps = inputs.batch(torch.as_tensor(rows[i:i + per], device=device))
            memory = net.memory(steps)
            m = len(obs)
            acts = encoder.actions(np.tile(np.arange(n), m))
            out.append(net.belief_from_memory(
                None if memory is None else memory.repeat_interleave(n, 0),
                obs.repeat_interleave(n, 0), acts).cpu().numpy())
    beliefs = np.ascontiguousarray(np.concatenate(out), dtype=np.float32)     # (R n, d_b)
    # the same belief decomposes the same: each distinct one once (a state policy's held-out
    # steps revisit a few hundred states)
    first, of = distinct_rows(beliefs)
    values = np.asarray(data.values, np.float64)[data.train_rows]
    index = BeliefIndex.build(b_tr, kind="flat")
    episode = row_episodes(corpus.episode_starts)[data.train_rows]
    parts = []               # blocks: (Q, k, d_b) float64, 110 MB at k 42, d_b 20
    for i in range(0, max(len(first), 1), QUERIES):
        dec = decompose(b_tr, beliefs[first[i:i + QUERIES]], k=k, values=values, index=index)
        parts.append((dec.residual, dec.value, support_episodes(
            b_tr, dec.rows, dec.weights, dec.neighbours, episode)[0]))
    residual, value, support = (np.concatenate(p) for p in zip(*parts))
    rng = np.random.default_rng(seed)
    sample = np.sort(rng.choice(len(b_tr), size=min(TYPICAL_SAMPLE, len(b_tr) // 2),
                                replace=False))
    keep = np.ones(len(b_tr), bool)
    keep[sample] = False
    typical = decompose(b_tr, b_tr[sample], k=k, values=values, index=index, selection=keep)
    return {"residual": np.asarray(residual, np.float64)[of].reshape(len(rows), n),
            "value": np.asarray(value, np.float64)[of].reshape(len(rows), n),
            "support": np.asarray(support, np.float64)[of].reshape(len(rows), n),
            "value_std": float(np.std(values)) if len(values) else 1.0,
            "p90": float(np.quantile(typical.residual, 0.9)), "distinct": int(len(first))}


def decisions(parts: dict, controllers: tuple[dict, ...]) -> list[np.ndarray]:
    """(R,) each of the ``controllers``' (their settings) action at every held-out step
    (:func:`choose`, epsilon the model's controller's)."""
    out = []
    for settings in controllers:
        config = ControllerConfig(**settings)
        _, _, chosen = choose(parts["residual"], parts["value"], config,
                              cap=residual_cap(config.residual_cap, parts["p90"]),
                              support=parts["support"], value_std=parts["value_std"])
        out.append(np.asarray(chosen, np.int64))
    return out


def valued(estimates: list[dict], span: tuple[float, float] | None = None) -> list[str]:
    """Per candidate, why its estimate is none ("" where it is an estimate): its lower bound
    not finite; outside ``span`` (lowest, highest: the held-out episodes' returns) by more
    than a tenth of its width (FQE diverged); its ``pairs`` (the held-out count of the pair
    its median decision takes, where given) below :data:`MIN_PAIRS` (FQE extrapolated)."""
    out = []
    slack = None if span is None else 0.1 * max(span[1] - span[0], 1e-12)
    for e in estimates:
        if e.get("screened"):
            out.append(f"fewer than {MIN_PAIRS} at {e['screened']:,} held-out steps drawn "
                       "at random: FQE's Q there would extrapolate (not fitted)")
        elif e.get("alone"):
            out.append("no other candidate has an estimate to weigh against it: not fitted")
        elif e["low"] is None or not np.isfinite(e["low"]):
            out.append("no interval")
        elif span is not None and not span[0] - slack <= e["estimate"] <= span[1] + slack:
            out.append("outside the held-out returns: FQE diverged")
        elif e.get("pairs", MIN_PAIRS) < MIN_PAIRS:
            out.append(f"fewer than {MIN_PAIRS}: FQE's Q there extrapolates")
        else:
            out.append("")
    return out


def pick(estimates: list[dict], span: tuple[float, float] | None = None) -> int:
    """The rule (module docstring): the index of the highest :func:`bounds` (the first of
    equals) among the candidates with an estimate (:func:`valued`); when the first (rule
    2's) has none, the log cannot weigh anything against it, and it is kept."""
    why = valued(estimates, span)
    if why[0]:
        return 0
    lows = np.where([bool(w) for w in why], -np.inf, bounds(estimates, span))
    return int(np.argmax(lows))   # argmax takes the first of equals: the more conservative


def bounds(estimates: list[dict], span: tuple[float, float] | None = None) -> np.ndarray:
    """(C,) each candidate's bound: its interval's ``low`` less its ``rare`` share (of
    decisions the held-out log hardly holds; 0 where not given) times the width of ``span``
    (the held-out returns' lowest and highest; none: 0)."""
    width = 0.0 if span is None else float(span[1] - span[0])
    return np.array([-np.inf if e["low"] is None else e["low"] - e.get("rare", 0.0) * width
                     for e in estimates], np.float64)


def pair_counts(observations: np.ndarray, logged: np.ndarray, n: int,
                chosen: list[np.ndarray]) -> list[np.ndarray]:
    """(R,) per candidate: how many held-out steps took, in the state of each held-out step
    (its observation (R, d_o), exactly: rule 2's finite state), the action the candidate
    decides there (its ``chosen`` (R,)); ``logged`` (R,) the actions the steps took."""
    _, state = distinct_rows(observations)
    table = np.bincount(state * n + logged, minlength=(int(state.max()) + 1) * n)
    return [table[state * n + np.asarray(c, np.int64)] for c in chosen]


def select_controller(net, inputs, data, norm, corpus, config, k: int, controllers,
                      progress=None) -> dict:
    """The selection of the module docstring among ``controllers`` (:func:`candidates`) on a
    trained model: {"chosen" (settings),
    "candidates" [{settings, estimate, low, high, agrees (the share of held-out steps where
    it decides the logged action), pairs (the held-out count of its median decision's
    pair), rare (the share of its decisions below MIN_PAIRS), bound (the rule's,
    :func:`bounds`), valued}], "episodes", "steps", "returns" (the held-out returns' lowest
    and highest), "rule", "seconds"}. ``config`` the model's BeliefConfig (its gamma, seed);
    ``progress``: FQE's member-steps, labelled. Runs with one thread in torch, FAISS and
    BLAS, as a control step and ``aoc evaluate``'s FQE do (FQE's parts fork:
    :mod:`aoc_cli.ope.parts`)."""
    with one_thread():
        return _select(net, inputs, data, norm, corpus, config, k, progress, controllers)


def _select(net, inputs, data, norm, corpus, config, k, progress, controllers) -> dict:
    started = time.perf_counter()
    rows, starts, cut = held_out_steps(corpus, data)
    n_eps = len(starts) - 1
    if progress is not None:
        progress(0, None, f"choosing the controller: {len(controllers)} candidates decide "
                          f"{len(rows):,} held-out steps")
    harm = "do_no_harm" in controllers[0]    # rule 7's premise: no finite state
    n = int(corpus.n_actions)
    logged = np.asarray(corpus.actions, np.int64)[rows]
    obs = np.asarray(corpus.observations)[rows]
    distinct = None
    if harm:
        chosen, held, screened = harm_candidates(net, inputs, data, norm, corpus, config, k,
                                                 rows, starts, controllers)
    else:
        parts = decompositions(net, inputs, data, norm, corpus, k, config.seed)
        chosen, distinct = decisions(parts, controllers), parts["distinct"]
        held, screened = pair_counts(obs, logged, n, chosen), [None] * len(chosen)
    fitted = [c for c in chosen if c is not None]
    if harm and len(fitted) == 1:     # nothing to weigh rule 7's against: kept unfitted
        fitted = []
    text = (f"choosing the controller: FQE of {len(fitted)} candidates on {n_eps:,} "
            "held-out episodes")
    tick = None if progress is None else (lambda done, total: progress(done, total, text))
    fits = iter(fqe_policies(obs, logged, np.asarray(corpus.rewards, np.float64)[rows],
                             starts, [np.eye(n)[c] for c in fitted], float(config.gamma),
                             FQE_STEPS, FQE_REFITS, seed=config.seed, progress=tick,
                             truncated=cut) if fitted else [])
    estimates, fqe_steps = [], 0
    for s, c, h, m in zip(controllers, chosen, held, screened):
        f = next(fits) if c is not None and fitted else {"estimate": None, "low": None,
                                                          "high": None}
        estimates.append({"settings": dict(s),
                          **{key: None if f[key] is None else float(f[key])
                             for key in ("estimate", "low", "high")},
                          "pairs": float(np.median(h)), "rare": float(np.mean(h < MIN_PAIRS)),
                          **({"agrees": float(np.mean(c == logged))} if m is None else
                             {"screened": m}),
                          **({"alone": True} if c is not None and not fitted else {})})
        if "steps" in f:
            fqe_steps = int(f["steps"])
    returns = np.add.reduceat(np.asarray(corpus.rewards, np.float64)[rows]
                              * float(config.gamma) ** _steps_in(starts), starts[:-1])
    span = (float(returns.min()), float(returns.max()))
    for e, why, bound in zip(estimates, valued(estimates, span), bounds(estimates, span)):
        e["bound"] = float(bound) if np.isfinite(bound) else None
        e["valued"] = not why
        if why:
            e["not_valued"] = why
    best = pick(estimates, span)
    return {"chosen": dict(controllers[best]), "candidates": estimates, "episodes": n_eps,
            "steps": int(len(rows)), **({} if distinct is None else {"distinct": distinct}),
            "rule": RULE + (NEAR if harm else ""),
            "min_pairs": MIN_PAIRS, "returns": list(span),
            "interval": f"+- {student_quantile(FQE_REFITS - 1):.3g} sd of {FQE_REFITS} refits",
            "fqe_steps": fqe_steps, "seconds": time.perf_counter() - started}


def recording_hook(corpus, config, k: int, recording: Recording, progress=None):
    """An ``inspect`` hook for :func:`aoc_cli.belief.train.train_model`: runs
    :func:`select_controller` and records its choice in ``recording`` (the ``controller``
    settings saved with the model, the ``settings`` reasons ``aoc train`` prints)."""

    def inspect(net, inputs, data, norm) -> dict:
        # rule 2's penalty, measured on the row values before training (aoc_cli.training.fit)
        record = recording.record
        harm = record.controller.get("do_no_harm") == "on"
        out = select_controller(net, inputs, data, norm, corpus, config, k,
                                HARM if harm else
                                candidates(record.controller.get("support_penalty")),
                                progress)
        record = record.with_controller(**out["chosen"])
        prior = {r["setting"]: r for r in record.settings["decided"]}
        names = tuple(out["chosen"])
        decided = [r for r in record.settings["decided"] if r["setting"] not in names]
        for i, name in enumerate(names):
            value = out["chosen"][name]
            measured = prior.get(name, {})
            # the penalty chosen is rule 2's bound: its measure stays in the record
            same = value is not None and measured.get("value") == value
            kept = {key: v for key, v in measured.items()
                    if key not in ("setting", "value", "why", "seconds")} if same else {}
            # rule 7 kept: why it decides stays beside why it was chosen
            show = same and "why" in measured and (harm or bool(kept))
            said = f"; {'' if harm else 'the penalty: '}{measured['why']}" if show else ""
            decided.append({
                "setting": name, "value": value,
                "why": (f"chosen among {len(out['candidates'])} controllers by {out['rule']} "
                        f"({out['episodes']:,} episodes, {out['steps']:,} steps; each "
                        "candidate's value below)" if i == 0 else
                        f"chosen with {names[0]}, by the same rule") + said,
                "seconds": out["seconds"], **kept})
        recording.record = record.with_settings(decided=decided, controller_selection=out)
        return {}

    return inspect


def _steps_in(starts: np.ndarray) -> np.ndarray:
    """(N,) each held-out step's index within its episode (``starts``: the (E + 1,) row
    offsets of the episodes)."""
    lengths = np.diff(starts)
    return np.arange(int(starts[-1])) - np.repeat(starts[:-1], lengths)
