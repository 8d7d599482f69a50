"""`aoc rollout NAME --env ENV`: run the controller (or a baseline) in an environment."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from aoc_cli.cli.common import FormatOption, get_store
from aoc_cli.errors import AocError
from aoc_cli.report import message, progress, resolve_format, write_object, write_records

#: Policies that need no model or index: they run on a corpus before anything is trained.
MODEL_FREE = ("zero", "random")


def parse_selection(items: list[str] | None, flag: str) -> dict[str, list[str]]:
    """``["policy=pi1,pi3", "system=normal"]`` -> ``{"policy": ["pi1", "pi3"], ...}``."""
    out: dict[str, list[str]] = {}
    for item in items or []:
        tag, sep, values = item.partition("=")
        if not sep or not tag or not values:
            raise AocError(f"{flag} expects TAG=VALUE[,VALUE...], got {item!r}")
        out.setdefault(tag.strip(), []).extend(v.strip() for v in values.split(",") if v.strip())
    return out


def register(app: typer.Typer) -> None:
    @app.command("rollout")
    def rollout_command(
        name: str = typer.Argument(..., help="Corpus name."),
        env: str = typer.Option(..., "--env", help="A built-in task (aoc collect --list) or a gymnasium id."),
        episodes: int = typer.Option(5, "--episodes", "-n", help="Episodes to run."),
        policy: str = typer.Option("aoc", "--policy", help="aoc, or a baseline: zero, random, 1nn, knn, 1nn-belief, knn-belief, bc, td3bc, cql, mpc (the last three with the bench extra)."),
        model: Optional[str] = typer.Option(None, "--model", help="Model id (default: the only one)."),
        index_id: str = typer.Option("default", "--index", help="Index id, e.g. a re-sampled index."),
        candidates: int = typer.Option(100, "--candidates", "-K", help="Candidate actions per step."),
        epsilon: Optional[float] = typer.Option(None, "--epsilon", help="Residual quantile of candidates kept, in (0, 1] (default: the task's, else 0.5)."),
        k: Optional[int] = typer.Option(None, "--k", help="Nearest corpus beliefs per query (default 2(d_b+1))."),
        residual_cap: Optional[float] = typer.Option(None, "--residual-cap", help="Also drop candidates whose residual exceeds this many times the corpus's typical p90 residual (default: no cap)."),
        sampler: str = typer.Option("uniform", "--sampler", help="uniform|bc"),
        select: Optional[List[str]] = typer.Option(None, "--select", help="Only rows with TAG=VALUE[,VALUE]."),
        exclude: Optional[List[str]] = typer.Option(None, "--exclude", help="No rows with TAG=VALUE[,VALUE]."),
        seed: int = typer.Option(0, "--seed", help="Seed of the first episode and of the candidates."),
        audit: Optional[Path] = typer.Option(None, "--audit", help="Write every decision to this HDF5 file."),
        plot: Optional[Path] = typer.Option(None, "--plot", help="Write a PNG of trajectories or residual/reward curves."),
        noise_after: Optional[int] = typer.Option(None, "--noise-after", help="Disturb actions after this step (OOD test)."),
        noise_std: float = typer.Option(0.5, "--noise-std", help="Disturbance std as a fraction of the action range."),
        ood_reference: Optional[Path] = typer.Option(None, "--ood-reference", help="Audit log of clean rollouts: flag steps against its per-step 3-sigma band instead of the running one."),
        fmt: Optional[str] = FormatOption,
    ) -> None:
        """Run episodes; print returns, success, OOD flags and residuals."""
        from aoc_cli.control import rollout
        from aoc_cli.envs import make_env
        from aoc_cli.rows import row_selection
        from aoc_cli.session import model_free_session, open_session

        fmt = resolve_format(fmt)
        if episodes < 1:
            raise AocError(f"--episodes must be >= 1, got {episodes}")
        store = get_store()
        from aoc_cli.store.paths import check_output

        for flag, path in (("--audit", audit), ("--plot", plot)):
            if path is not None:
                check_output(path, flag, store.root)
        if noise_std != noise_std or noise_std < 0 or noise_std == float("inf"):
            raise AocError(f"--noise-std must be a finite number >= 0, got {noise_std}")
        corpus = store.corpus(name)
        config = task_config(env, candidates=candidates, epsilon=epsilon, k=k, sampler=sampler,
                             residual_cap=residual_cap)
        environment = make_env(env)
        selection = row_selection(corpus, parse_selection(select, "--select"),
                                  parse_selection(exclude, "--exclude"))
        from aoc_cli.control.rollout import action_space_of

        action_space = action_space_of(environment)
        if policy in MODEL_FREE:
            # these act without looking at the data: no model or index is needed (or opened)
            session = model_free_session(corpus, action_space)
        else:
            session = open_session(corpus, model, index_id, config, selection, seed,
                                   action_space)
        reference = None
        if ood_reference is not None:
            if policy in MODEL_FREE:
                raise AocError(f"--ood-reference needs the AOC controller's residuals; "
                               f"--policy {policy} has none")
            from aoc_cli.control.run import reference_from_audit

            reference = reference_from_audit(session, ood_reference)
        baseline = None
        if policy != "aoc":
            from aoc_cli.baselines import make_baseline

            baseline = make_baseline(policy, session, environment, seed=seed)
        with progress() as p:
            results, summary = rollout(session, environment, episodes, seed=seed, policy=baseline,
                                       audit=str(audit) if audit else None,
                                       noise_after=noise_after, noise_std=noise_std, progress=p,
                                       reference=reference)
        if plot is not None:
            _plot(env, results, plot, noise_after)
            message(f"wrote {plot}")
        if audit is not None:
            message(f"wrote the audit log {audit}")
        rows = [r.summary() for r in results]
        if fmt == "json":
            write_object({"episodes": rows, "summary": summary}, "json")
        elif fmt == "table":
            write_records(rows, "table", title=f"{policy} on {env} ({corpus.name})")
            write_object(summary, "table", title="summary")
        else:
            write_records(rows, fmt)
            message("summary: " + ", ".join(f"{k}={v}" for k, v in summary.items()))


def task_config(env: str, **given):
    """ControllerConfig from the flags given, else the task's own settings, else the paper's."""
    from aoc_cli.control import ControllerConfig
    from aoc_cli.envs import TASKS

    task = TASKS.get(env)
    settings = dict(task.controller) if task is not None else {}
    settings.update({k: v for k, v in given.items() if v is not None})
    return ControllerConfig(**settings).check()


def _plot(env_name: str, results, path: Path, noise_after) -> None:
    import numpy as np

    from aoc_cli.envs import TASKS
    from aoc_cli.report.plots import plot_rollout_curves

    task = TASKS.get(env_name)
    if task is not None and hasattr(task, "plot_trajectories") and \
            np.asarray(results[0].observations).shape[-1] == 2:
        paths = [np.asarray(r.observations) for r in results]
        task.plot_trajectories(paths, path, title=f"{env_name}: {len(paths)} rollouts")
    else:
        plot_rollout_curves(results, path, title=env_name, noise_after=noise_after)
