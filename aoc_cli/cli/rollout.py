"""`aoc rollout NAME --env ENV`: run the controller (or a baseline) in an environment."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from aoc_cli.cli.common import (CandidatesOption, CorpusArgument, EpisodesOption,
                                EpsilonOption, ExcludeOption, FormatOption, IndexOption,
                                KOption, MinSupportOption, ModelOption, PolicyName, PolicyOption,
                                ResidualCapOption, SamplerName, SamplerOption, SelectOption,
                                SupportPenaltyOption, choice, get_store, parse_selection)
from aoc_cli.errors import AocError
from aoc_cli.report import (ProgressBar, message, resolve_format, write_object,
                            write_records)

#: Policies that need no model or index: they run on a corpus before anything is trained.
MODEL_FREE = ("zero", "random")


def register(app: typer.Typer) -> None:
    @app.command("rollout")
    def rollout_command(
        name: CorpusArgument,
        env: Annotated[str, typer.Option(
            "--env", help="A built-in task (aoc collect --list) or a gymnasium id.")],
        episodes: EpisodesOption = 5,
        policy: PolicyOption = PolicyName.aoc,
        model: ModelOption = None,
        index_id: IndexOption = "default",
        candidates: CandidatesOption = None,
        epsilon: EpsilonOption = None,
        k: KOption = None,
        min_support: MinSupportOption = None,
        support_penalty: SupportPenaltyOption = None,
        residual_cap: ResidualCapOption = None,
        sampler: SamplerOption = SamplerName.uniform,
        select: SelectOption = None,
        exclude: ExcludeOption = None,
        seed: Annotated[int, typer.Option(
            "--seed", help="Seed of the first episode and of the candidates.")] = 0,
        audit: Annotated[Optional[Path], typer.Option(
            "--audit", help="Write every decision to this HDF5 file.")] = None,
        plot: Annotated[Optional[Path], typer.Option(
            "--plot", help="Write a PNG of trajectories or residual/reward curves.")] = None,
        noise_after: Annotated[Optional[int], typer.Option(
            "--noise-after", help="Disturb actions after this step (OOD test).")] = None,
        noise_std: Annotated[float, typer.Option(
            "--noise-std", help="Disturbance std as a fraction of the action range.")] = 0.5,
        ood_reference: Annotated[Optional[Path], typer.Option(
            "--ood-reference", help="Audit log of clean rollouts: flag steps against its "
                                    "per-step 3-sigma band instead of the running one.")] = None,
        fmt: FormatOption = None,
    ) -> None:
        """Run episodes; print returns, success, OOD flags and residuals."""
        from aoc_cli.control import ControllerConfig, rollout
        from aoc_cli.envs import make_env
        from aoc_cli.rows import row_selection

        fmt = resolve_format(fmt)
        policy, sampler = choice(policy), choice(sampler)
        store = get_store()
        _check_arguments(store, episodes, noise_std, audit, plot)
        corpus = store.corpus(name)
        config = ControllerConfig.for_task(env, candidates=candidates, epsilon=epsilon, k=k,
                                           sampler=sampler, residual_cap=residual_cap,
                                           min_support=min_support,
                                           support_penalty=support_penalty)
        environment = make_env(env)
        selection = row_selection(corpus, parse_selection(select, "--select"),
                                  parse_selection(exclude, "--exclude"))
        session, baseline = _policy(policy, corpus, environment, model, index_id, config,
                                    selection, seed)
        reference = _ood_reference(policy, session, ood_reference)
        with ProgressBar("rollout", episodes) as p:
            results, summary = rollout(session, environment, episodes, seed=seed, policy=baseline,
                                       audit=str(audit) if audit else None,
                                       noise_after=noise_after, noise_std=noise_std, progress=p,
                                       reference=reference)
        if plot is not None:
            _plot(env, results, plot, noise_after)
            message(f"wrote {plot}")
        if audit is not None:
            message(f"wrote the audit log {audit}")
        _print(results, summary, fmt, f"{policy} on {env} ({corpus.name})")


def _check_arguments(store, episodes: int, noise_std: float, audit, plot) -> None:
    """Refuse bad numbers and output paths (into the store) before any work."""
    from aoc_cli.store.paths import check_output

    if episodes < 1:
        raise AocError(f"--episodes must be >= 1, got {episodes}")
    for flag, path in (("--audit", audit), ("--plot", plot)):
        if path is not None:
            check_output(path, flag, store.root)
    if noise_std != noise_std or noise_std < 0 or noise_std == float("inf"):
        raise AocError(f"--noise-std must be a finite number >= 0, got {noise_std}")


def _ood_reference(policy: str, session, path):
    """The per-step OOD band of an audit log of clean rollouts (--ood-reference), or None."""
    if path is None:
        return None
    if policy in MODEL_FREE:
        raise AocError(f"--ood-reference needs the AOC controller's residuals; "
                       f"--policy {policy} has none")
    from aoc_cli.control.run import reference_from_audit

    return reference_from_audit(session, path)


def _policy(policy: str, corpus, environment, model, index_id, config, selection, seed):
    """(session, baseline or None): the session the policy acts in (model-free for zero and
    random: no model or index is needed, or opened) and the baseline that acts, if not aoc."""
    from aoc_cli.control.rollout import action_space_of
    from aoc_cli.control import model_free_session, open_session

    action_space = action_space_of(environment)
    if policy in MODEL_FREE:
        session = model_free_session(corpus, action_space)
    else:
        session = open_session(corpus, model, index_id, config, selection, seed, action_space)
    if policy == "aoc":
        return session, None
    from aoc_cli.baselines import make_baseline

    return session, make_baseline(policy, session, environment, seed=seed)


def _print(results, summary: dict, fmt: str, title: str) -> None:
    rows = [r.summary() for r in results]
    if fmt == "json":
        write_object({"episodes": rows, "summary": summary}, "json")
    elif fmt == "table":
        write_records(rows, "table", title=title)
        write_object(summary, "table", title="summary")
    else:
        write_records(rows, fmt)
        message("summary: " + ", ".join(f"{k}={v}" for k, v in summary.items()))


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
