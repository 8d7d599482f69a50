"""``aoc collect TASK --steps N --name NAME``: run a built-in task's behaviour policies into a
corpus; ``aoc collect --list`` shows the tasks. Parses and prints only; the work is in
:mod:`aoc_cli.envs`."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from aoc_cli.cli.common import (EpisodesOption, FormatOption, RayAddressOption, WorkersOption,
                                get_store)
from aoc_cli.errors import AocError
from aoc_cli.report.output import ProgressBar, message, write_records

LIST_COLUMNS = ["name", "gym_id", "horizon", "default_steps", "default_episodes", "policies",
                "success"]


def register(app: typer.Typer) -> None:
    @app.command("collect")
    def collect_cmd(
        task: Optional[str] = typer.Argument(
            None, help="Built-in task: pendulum-het, pendulum-het-upright, maze, two-gates, "
                       "lunar, ward, icu-sepsis, icu-sepsis-terminate (see --list)."),
        steps: Annotated[Optional[int], typer.Option(
            "--steps", help="Rows to collect (default: the task's, see --list).")] = None,
        episodes: EpisodesOption = None,
        name: Optional[str] = typer.Option(None, "--name", help="Name of the corpus to write."),
        seed: int = typer.Option(0, "--seed", help="Random seed: same seed, same corpus."),
        behaviour: str = typer.Option(
            "mix", "--behaviour", help="mix: the task's behaviour policies; replay "
                                       "(pendulum-het, pendulum-het-upright, lunar): an agent "
                                       "that starts random and improves, as a replay buffer."),
        policy: Optional[str] = typer.Option(
            None, "--policy", help="icu-sepsis: the behaviour to log, clinicians (default) or "
                                   "random."),
        overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing corpus."),
        list_tasks: bool = typer.Option(False, "--list", help="List the tasks and their defaults."),
        csv_dir: Optional[str] = typer.Option(
            None, "--csv", help="ward: write the log as CSV files DIR/NAME.csv and "
                                "DIR/NAME-static.csv (for `aoc ingest --static`) instead of a "
                                "corpus."),
        workers: WorkersOption = None,
        ray_address: RayAddressOption = None,
        chunk: Annotated[Optional[int], typer.Option(
            "--chunk", help="With --workers: rows (or, with --episodes, episodes) per "
                            "independently seeded chunk (default 100000 rows, 1000 episodes; "
                            "README, 'Collect on several workers').")] = None,
        fmt: FormatOption = None,
    ) -> None:
        """Run a built-in task's behaviour policies and store the data as a corpus."""
        from aoc_cli.envs import TASKS, get_task

        if list_tasks:
            write_records([t.describe() for t in TASKS.values()], fmt, columns=LIST_COLUMNS,
                          title="built-in tasks")
            return
        if task is None:
            raise AocError("give a task to collect (one of " + ", ".join(TASKS)
                           + "), or --list to see them")
        t = get_task(task)
        if behaviour not in t.behaviours:
            raise AocError(f"--behaviour {behaviour!r}: task {task!r} has "
                           f"{', '.join(t.behaviours)}")
        if policy is not None and not t.extra.get("choose_policy"):
            raise AocError(f"--policy: task {task!r} logs its own mix of policies "
                           f"({', '.join(t.policies)}); --policy is for icu-sepsis")
        if policy is not None and policy not in t.policies:
            raise AocError(f"--policy {policy!r}: task {task!r} has "
                           f"{' or '.join(t.policies)}")
        if name is None:
            raise AocError(f"give the corpus name: aoc collect {task} --name NAME")
        for flag, value in (("--steps", steps), ("--episodes", episodes),
                            ("--workers", workers), ("--chunk", chunk)):
            if value is not None and value <= 0:
                raise AocError(f"{flag} must be a positive integer, got {value}")
        if steps is not None and episodes is not None:
            raise AocError("give --steps or --episodes, not both")
        if csv_dir is not None:
            write = t.extra.get("write_csv")
            if write is None:
                raise AocError(f"--csv: task {task!r} has no CSV form (ward has)")
            if steps is not None:
                raise AocError("--csv writes whole stays: give --episodes, not --steps")
            from aoc_cli.store.paths import check_output

            check_output(csv_dir, "--csv", get_store().root, folder=True)
            paths = write(csv_dir, name, episodes or t.default_episodes, seed)
            message(f"wrote {paths[0]} and {paths[1]}: ingest them with `aoc ingest "
                    f"{paths[0]} --name {name} --id-column patient --time-column hour "
                    f"--static {paths[1]} --discrete-actions --tag-column clinician`")
            return
        store = get_store()
        from aoc_cli.store import check_name, writing_corpus

        with writing_corpus(store.root, check_name(name)):
            if store.exists(name) and not overwrite:
                raise AocError(f"corpus {name!r} already exists in {store.root}: pass "
                               "--overwrite to replace it, or choose another --name")
            if workers is None and ray_address is None:
                corpus, summary = _collect(store, t, task, name, steps, episodes, seed,
                                           overwrite, behaviour, policy)
            else:
                corpus, summary = _collect_chunks(store, task, name, steps, episodes, seed,
                                                  overwrite, behaviour, workers, ray_address,
                                                  chunk, policy)
        message(f"wrote corpus {name!r}: {corpus.n_rows} rows, {corpus.n_episodes} episodes "
                f"of {task} (seed {seed}, hash {corpus.hash}) to {corpus.path}")
        write_records(summary, fmt, title=f"behaviour policies of {name}")


def _collect(store, t, task, name, steps, episodes, seed, overwrite, behaviour="mix",
             policy=None):
    """Run the task's policies and write the corpus: (corpus, per-policy summary)."""
    from aoc_cli.envs import collect

    with ProgressBar(f"collect {t.name}") as bar:
        data, summary = collect(task, steps=steps, episodes=episodes, seed=seed,
                                progress=bar, behaviour=behaviour, policy=policy)
    return store.write(name, data, overwrite=overwrite), summary


def _collect_chunks(store, task, name, steps, episodes, seed, overwrite, behaviour, workers,
                    address, chunk, policy=None):
    """Independently seeded chunks as Ray tasks (aoc_cli.envs.chunked): (corpus, summary)."""
    from aoc_cli.envs.chunked import CHUNK_EPISODES, CHUNK_STEPS, collect_chunked

    with ProgressBar(f"collect {task} in chunks") as bar:
        data, summary = collect_chunked(
            task, steps, episodes, seed, workers=workers, address=address,
            chunk_steps=chunk or CHUNK_STEPS, chunk_episodes=chunk or CHUNK_EPISODES,
            progress=bar, behaviour=behaviour, policy=policy)
    return store.write(name, data, overwrite=overwrite), summary
