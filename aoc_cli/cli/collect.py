"""``aoc collect TASK --steps N --name NAME``: run a built-in task's behaviour policies into a
corpus; ``aoc collect --list`` shows the tasks. Parses and prints only; the work is in
:func:`aoc_cli.api.collect`."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import (EpisodesOption, FormatOption, RayAddressOption, WorkersOption,
                                state)
from aoc_cli.errors import AocError
from aoc_cli.cli.output import ProgressBar, message, write_records

LIST_COLUMNS = ["name", "gym_id", "horizon", "default_steps", "default_episodes", "policies",
                "success"]


def register(app: typer.Typer) -> None:
    @app.command("collect")
    def collect_cmd(
        task: Optional[str] = typer.Argument(
            None, help="Built-in task: pendulum-het, pendulum-het-upright, maze, two-gates, "
                       "lunar, ward, icu-sepsis, icu-sepsis-terminate, icu-cohort (see --list)."),
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
        if list_tasks or task is None:
            tasks = aoc_cli.tasks()
            if task is None and not list_tasks:
                raise AocError("give a task to collect (one of " + ", ".join(
                    t["name"] for t in tasks) + "), or --list to see them")
            write_records(tasks, fmt, columns=LIST_COLUMNS, title="built-in tasks")
            return
        with ProgressBar("collect") as bar:
            done = aoc_cli.collect(task, name, store=state.store, steps=steps, episodes=episodes,
                                   seed=seed, behaviour=behaviour, policy=policy,
                                   overwrite=overwrite, workers=workers, ray_address=ray_address,
                                   chunk=chunk, csv=csv_dir, progress=bar)
        if csv_dir is not None:
            message(f"wrote {done[0]} and {done[1]}: ingest them with `aoc ingest "
                    f"{done[0]} --name {name} --id-column patient --time-column hour "
                    f"--static {done[1]} --discrete-actions --tag-column clinician`")
            return
        corpus = done.corpus
        message(f"wrote corpus {name!r}: {corpus.n_rows} rows, {corpus.n_episodes} episodes "
                f"of {task} (seed {seed}, hash {corpus.hash}) to {corpus.path}")
        write_records(done.summary, fmt, title=f"behaviour policies of {name}")
