"""`aoc evaluate NAME --data HELD_OUT`: decide every logged step of a corpus and score the
decisions against what was logged. Parses and prints only; the work is in
:mod:`aoc_cli.control.evaluate`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Optional

import typer

from aoc_cli.cli.common import (CandidatesOption, CorpusArgument, EpsilonOption,
                                FormatOption, IndexOption, KOption, MinSupportOption, ModelOption,
                                RayAddressOption, SupportPenaltyOption, WithoutEpisodesOption,
                                WithoutOption, WorkersOption, get_store, parse_removal)
from aoc_cli.errors import AocError, warn
from aoc_cli.report import resolve_format, write_object, write_records
from aoc_cli.settings import SMALL_LOG_ROWS

IMITATION_COLUMNS = ["method", "accuracy", "balanced_accuracy", "auc", "majority_accuracy",
                     "mae", "r2"]
VALUE_COLUMNS = ["method", "value_r2", "value_mae", "value_spearman", "agreement",
                 "action_distance"]


def register(app: typer.Typer) -> None:
    @app.command("evaluate")
    def evaluate_command(
        name: CorpusArgument,
        data: Annotated[str, typer.Option(
            "--data", help="Held-out corpus to score (same spaces), or NAME itself: each "
                           "episode is then decided without its own rows.")],
        baselines: Annotated[str, typer.Option(
            "--baselines", help="Baselines on the same steps, comma-separated: knn (nearest "
                                "rows on standardised inputs), bc (the model's own head); none "
                                "for neither.")] = "knn,bc",
        steps_file: Annotated[Optional[Path], typer.Option(
            "--steps", help="Write one JSON record per step to this JSONL file.")] = None,
        model: ModelOption = None,
        index_id: IndexOption = "default",
        candidates: CandidatesOption = None,
        epsilon: EpsilonOption = None,
        k: KOption = None,
        min_support: MinSupportOption = None,
        support_penalty: SupportPenaltyOption = None,
        exact: Annotated[Optional[bool], typer.Option(
            "--exact/--ivf", help="Search the index exactly for every step, or an IVF structure "
                                  "built for the run (default: exact up to "
                                  f"{SMALL_LOG_ROWS:,} corpus rows, IVF beyond: ~10x faster, "
                                  "recall of the nearest rows ~0.9999).")] = None,
        seed: Annotated[int, typer.Option(
            "--seed", help="Seed of the candidates (value mode, continuous actions), the "
                           "bootstrap and FQE.")] = 0,
        ope_names: Annotated[Optional[str], typer.Option(
            "--ope", help="Offline policy evaluation of the decisions (value mode): pdwis, "
                          "wdr, fqe, comma-separated, or none (default: all three when the "
                          "held-out log has rewards and discrete actions).")] = None,
        propensity: Annotated[Optional[str], typer.Option(
            "--propensity", help="Corpus column of the behaviour's probability of each "
                                 "logged action (default: 'propensity' when the log has it, "
                                 "else an imitation model estimates them).")] = None,
        ope_gamma: Annotated[float, typer.Option(
            "--ope-gamma", help="Discount of the value the OPE estimates (1: the mean "
                                "undiscounted return of an episode).")] = 1.0,
        fqe_steps: Annotated[Optional[int], typer.Option(
            "--fqe-steps", help="Gradient steps of fitted Q evaluation (default: about 30 "
                                "passes over the log, 1,500 to 6,000).")] = None,
        fqe_refits: Annotated[Optional[int], typer.Option(
            "--fqe-refits", help="Refits on resampled episodes behind FQE's interval, each a "
                                 "fifth of the fit's steps (default 10; 0: one fit, the "
                                 "interval then leaves the model's own error out).")] = None,
        workers: WorkersOption = None,
        ray_address: RayAddressOption = None,
        without: WithoutOption = None,
        without_episodes: WithoutEpisodesOption = None,
        fmt: FormatOption = None,
    ) -> None:
        """Decide every logged step of a held-out corpus in batches and score the decisions
        (accuracy, AUC, calibration or value R^2; residuals; baselines on the same steps)."""
        from aoc_cli.cli.explain import _collected_task
        from aoc_cli.control import ControllerConfig
        from aoc_cli.control.evaluate import evaluate, step_records
        from aoc_cli.report.output import ProgressBar
        from aoc_cli.control import open_session

        from aoc_cli.control.ope_eval import OPESettings, parse_estimators

        fmt = resolve_format(fmt)
        names = [b.strip() for b in baselines.split(",")]
        ope = None
        if any(v is not None for v in (ope_names, propensity, fqe_steps, fqe_refits)) \
                or ope_gamma != 1.0:
            if fqe_steps is not None and fqe_steps < 1:
                raise AocError(f"--fqe-steps must be >= 1, got {fqe_steps}")
            if fqe_refits is not None and (fqe_refits < 0 or fqe_refits == 1):
                raise AocError(f"--fqe-refits must be 0 or at least 2, got {fqe_refits}")
            if not 0.0 < ope_gamma <= 1.0:
                raise AocError(f"--ope-gamma must be in (0, 1], got {ope_gamma}")
            ope = OPESettings(parse_estimators(ope_names), gamma=ope_gamma,
                              propensity=propensity, fqe_steps=fqe_steps, seed=seed,
                              **({} if fqe_refits is None else {"fqe_refits": fqe_refits}))
        store = get_store()
        corpus = store.corpus(name)
        held_out = corpus if data == name else store.corpus(data)
        config = ControllerConfig.for_task(_collected_task(corpus), candidates=candidates,
                                           epsilon=epsilon, k=k, residual_cap=None,
                                           min_support=min_support,
                                           support_penalty=support_penalty)
        removal = parse_removal(corpus, without, without_episodes)
        if removal is not None and (workers is not None or ray_address is not None):
            raise AocError("--without runs in one process: drop --workers / --ray-address")
        session = open_session(corpus, model, index_id, config, seed=seed)
        with ProgressBar(f"evaluate {name} on {data}", held_out.n_rows,
                         transient=True) as on_progress:
            if workers is None and ray_address is None:
                summary, res = evaluate(session, held_out, names, seed=seed,
                                        progress=on_progress, exact=exact, ope=ope)
            else:  # the chunks of episodes as Ray tasks (aoc_cli.control.evaluate_ray)
                from aoc_cli.control.evaluate_ray import evaluate_on_ray

                if workers is not None and workers < 1:
                    raise AocError(f"--workers must be >= 1, got {workers}")
                summary, res = evaluate_on_ray(store.root, name, data, session.model.id,
                                               index_id, config, names, seed=seed, exact=exact,
                                               workers=workers, address=ray_address,
                                               progress=on_progress, ope=ope)
        if removal is not None:
            summary["what_if"] = _what_if(session, held_out, names, seed, exact, removal, res)
        if steps_file is not None:
            from aoc_cli.store import atomic_path

            with atomic_path(steps_file, suffix=".jsonl") as tmp:
                with open(tmp, "w") as fh:
                    for rec in step_records(session, held_out, res):
                        fh.write(json.dumps(rec) + "\n")
        for text in summary.get("ope_warnings", []):
            warn(text)
        _print(summary, fmt)


def _what_if(session, held_out, names, seed, exact, removal, before) -> dict:
    """The same steps decided again without ``removal``'s rows, and what changed."""
    from aoc_cli.control.evaluate import evaluate
    from aoc_cli.control.ope_eval import OPESettings
    from aoc_cli.control.whatif import what_if_steps
    from aoc_cli.report.output import ProgressBar

    keep = removal.keep(None)
    with ProgressBar(f"without {removal.label}", held_out.n_rows,
                     transient=True) as on_progress:
        summary, after = evaluate(session, held_out, [], seed=seed, progress=on_progress,
                                  exact=exact, selection=keep,
                                  ope=OPESettings(estimators=()))
    return what_if_steps(before, after, removal, session.corpus, summary)


def _method_rows(summary: dict) -> list[dict]:
    own = "abc" if summary["mode"] == "imitation" else "aoc"
    flat = {k: v for k, v in summary.items() if not isinstance(v, (dict, list))}
    rows = [{"method": own, **flat}]
    for method, rec in summary["baselines"].items():
        rows.append({"method": method, **rec})
    return rows


def _ope_rows(summary: dict) -> list[dict]:
    """One row per policy: each estimator's estimate [low, high] and the ESS."""
    def cell(e):
        return None if e is None else f"{e['estimate']:.4f} [{e['low']:.4f}, {e['high']:.4f}]"

    rows = [{"policy": "aoc", "ess": summary["ess"],
             **{k: cell(v) for k, v in summary["policy_value"].items()}}]
    for name, rec in summary["baselines"].items():
        if "policy_value" in rec:
            rows.append({"policy": name, "ess": rec["ess"],
                         **{k: cell(v) for k, v in (rec["policy_value"] or {}).items()}})
    rows.append({"policy": "behaviour", "mean_return": cell(summary["behaviour_value"])})
    return rows


def _print(summary: dict, fmt: str) -> None:
    if fmt in ("json", "jsonl"):
        write_object(summary, fmt)
        return
    columns = IMITATION_COLUMNS if summary["mode"] == "imitation" else VALUE_COLUMNS
    rows = _method_rows(summary)
    present = [c for c in columns if any(r.get(c) is not None for r in rows)]
    if fmt == "csv":
        extra = ["steps", "extrapolating_share", "heterogeneity_share"]
        for r in rows[1:]:
            for c in extra:
                r[c] = rows[0][c]
        write_records(rows, "csv", columns=present + extra)
        return
    head = {k: summary[k] for k in ("mode", "corpus", "model", "data", "own_episode_left_out",
                                    "steps", "episodes", "extrapolating_share",
                                    "heterogeneity_share", "support_max", "search", "seconds",
                                    "steps_per_second")}
    res = summary["residual"]
    head["residual p50 / p90 / p99"] = f"{res['p50']:.4g} / {res['p90']:.4g} / {res['p99']:.4g}"
    head["typical residual"] = res["typical"]
    write_object(head, "table", title=f"aoc evaluate {summary['corpus']} on {summary['data']}")
    write_records(rows, "table", columns=present, title="decisions against the log")
    if "what_if" in summary:
        w = summary["what_if"]
        head = {"without": f"{w['without']['label']} ({w['without']['rows']} rows, "
                           f"{w['without']['episodes']} episodes)",
                "steps": w["steps"], "decisions flipped": w["flipped"],
                "flip share": w["flip_share"],
                "steps whose subset lost a row": w["support_removed_steps"],
                "residual change (mean)": w["residual_change"]["mean"]}
        for key in ("value_change", "score_change"):
            if key in w:
                head[key.replace("_", " ") + " (mean / mean abs)"] = \
                    f"{w[key]['mean']:.4g} / {w[key]['mean_abs']:.4g}"
        head.update({f"{k} after": v for k, v in w["after"].items()})
        write_object(head, "table", title="what if")
    if "policy_value" in summary:
        write_records(_ope_rows(summary), "table",
                      title=f"policy value from the log alone (propensities: "
                            f"{summary['ope']['propensity']})")
    if "confusion" in summary:
        n = len(summary["confusion"])
        write_records([{"logged": i, **{f"decided {j}": summary["confusion"][i][j]
                                        for j in range(n)}} for i in range(n)], "table",
                      title="confusion (steps)")
        write_records([b for b in summary["calibration"] if b["steps"]], "table",
                      title="calibration (score of action 1, or the top score)")
