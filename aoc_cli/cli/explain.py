"""`aoc explain NAME`: the supporting examples, weights and residual behind a decision.
Parses and prints only; the work is in :func:`aoc_cli.api.explain`, the tables in
:mod:`aoc_cli.cli.explain_view`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, List, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import (CorpusArgument, FormatOption, IndexOption, ModelOption,
                                WithoutEpisodesOption, WithoutOption, deciding, parse_episodes,
                                parse_selection, state)
from aoc_cli.errors import AocError
from aoc_cli.cli.output import message, resolve_format
from aoc_cli.cli.explain_view import write_explained
from aoc_cli.store import DEFAULT_INDEX


def register(app: typer.Typer) -> None:
    @app.command("explain")
    @deciding
    def explain_command(
        name: CorpusArgument,
        input: Annotated[Optional[str], typer.Option(
            "--input", "-i", help="JSONL queries (a file, or - for stdin).")] = None,
        audit: Annotated[Optional[Path], typer.Option(
            "--audit", help="An audit log written by `aoc rollout --audit`.")] = None,
        data: Annotated[Optional[str], typer.Option(
            "--data", help="A corpus whose logged step to explain (--episode, --step): NAME "
                           "itself, or held-out episodes of the same spaces. Prints the "
                           "controller's decision there and what supports the logged "
                           "action.")] = None,
        episode: Annotated[int, typer.Option(
            "--episode", help="Episode of the audit log or of --data.")] = 0,
        step: Annotated[int, typer.Option("--step", help="Step of that episode.")] = 0,
        compare: Annotated[Optional[List[str]], typer.Option(
            "--compare", help="Actions to explain side by side, e.g. --compare 0 --compare 1 "
                              "or --compare 0.5,-1.")] = None,
        model: ModelOption = None,
        index_id: IndexOption = DEFAULT_INDEX,
        controller: dict = None,
        seed: Annotated[int, typer.Option("--seed", help="Seed of the candidates.")] = 0,
        without: WithoutOption = None,
        without_episodes: WithoutEpisodesOption = None,
        html: Annotated[Optional[Path], typer.Option(
            "--html", help="Also write a decision page to this HTML file (self-contained: "
                           "the decision in words, a card per supporting row with its "
                           "history, the best action not chosen; with --audit or --steps an "
                           "overview of the episode's decisions).")] = None,
        steps_file: Annotated[Optional[Path], typer.Option(
            "--steps", help="An `aoc evaluate --steps` file: write its overview page to "
                            "--html.")] = None,
        fmt: FormatOption = None,
    ) -> None:
        """Explain decisions: from JSONL queries, a recorded step of an audit log, or a logged
        step of a corpus."""
        fmt = resolve_format(fmt)
        done = aoc_cli.explain(name, store=state.store, queries=input, audit=audit, data=data,
                               episode=episode, step=step,
                               compare=[_parse_action(c) for c in compare or []], model=model,
                               index_id=index_id, controller=controller, seed=seed,
                               without=parse_selection(without, "--without"),
                               without_episodes=parse_episodes(without_episodes), html=html,
                               steps_file=steps_file)
        if done.html is not None:
            message(f"wrote {done.html}")
        if done.records:
            write_explained(done.records, fmt)


def _parse_action(text: str):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise AocError(f"--compare expects numbers (comma-separated for several dims), "
                       f"got {text!r}") from None
    return values if len(values) > 1 else values[0]
