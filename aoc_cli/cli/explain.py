"""`aoc explain NAME`: the supporting examples, weights and residual behind a decision."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, List, Optional

import typer

from aoc_cli.cli.common import (CandidatesOption, CorpusArgument, EpsilonOption, FormatOption,
                                IndexOption, KOption, MinSupportOption, ModelOption,
                                ResidualCapOption, SupportPenaltyOption,
                                WithoutEpisodesOption, WithoutOption, get_store,
                                parse_removal)
from aoc_cli.errors import AocError
from aoc_cli.report import resolve_format, write_object, write_records


def register(app: typer.Typer) -> None:
    @app.command("explain")
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
        index_id: IndexOption = "default",
        candidates: CandidatesOption = None,
        epsilon: EpsilonOption = None,
        k: KOption = None,
        min_support: MinSupportOption = None,
        support_penalty: SupportPenaltyOption = None,
        residual_cap: ResidualCapOption = None,
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
        from aoc_cli.cli.explain_page import check_html, steps_overview, write_html
        from aoc_cli.control import ControllerConfig

        fmt = resolve_format(fmt)
        store = get_store()
        if html is not None:
            check_html(html, store.root)
        if steps_file is not None:
            if html is None or any(x is not None for x in (input, audit, data)):
                raise AocError("--steps FILE writes an overview page: give --html FILE and "
                               "none of --input, --audit, --data")
            steps_overview(store.corpus(name), steps_file, html, model, index_id)
            return
        if sum(x is not None for x in (input, audit, data)) != 1:
            raise AocError("give one of --input FILE|- (JSONL queries), --audit FILE --episode E "
                           "--step T (a recorded decision) or --data CORPUS --episode E --step T "
                           "(a logged step)")
        corpus = store.corpus(name)
        config = ControllerConfig.for_task(_collected_task(corpus), candidates=candidates,
                                           epsilon=epsilon, k=k, residual_cap=residual_cap,
                                           min_support=min_support,
                                           support_penalty=support_penalty)
        opened = dict(model_id=model, index_id=index_id, config=config, seed=seed)
        removal = parse_removal(corpus, without, without_episodes)
        session = None
        if data is not None:
            source = corpus if data == name else store.corpus(data)
            records = _logged_step(corpus, source, episode, step, opened, removal)
        elif audit is not None:
            records, session = _recorded_step(corpus, audit, episode, step, opened, removal)
        else:
            records = _queries(corpus, input, compare, opened, removal)
        if html is not None:
            write_html(html, records, corpus, session=session, audit=audit, episode=episode,
                       step=step)
        _print(records, fmt)


def _logged_step(corpus, source, episode: int, step: int, opened: dict,
                 removal) -> list[dict]:
    """``--data``: the decision at a logged step of ``source`` and what supports the logged
    action there."""
    from aoc_cli.control import explain_logged_step
    from aoc_cli.control import open_session

    return explain_logged_step(open_session(corpus, **opened), source, episode, step,
                               removal=removal)


def _recorded_step(corpus, audit: Path, episode: int, step: int, opened: dict,
                   removal) -> tuple[list[dict], object]:
    """``--audit``: a recorded decision replayed with its recorded inputs and settings;
    (records, the session)."""
    from aoc_cli.control import ControllerConfig, open_session, read_audit_step, replay_decision
    from aoc_cli.control.explain import explain_decisions
    from aoc_cli.control.records import label_of
    from aoc_cli.store import action_labels

    recorded = read_audit_step(audit, episode, step)
    meta = recorded["meta"]
    config = ControllerConfig(**meta["config"]).check() if meta.get("config") \
        else opened["config"]
    session = open_session(corpus, meta.get("model", opened["model_id"]),
                           meta.get("index", opened["index_id"]), config, seed=opened["seed"])
    decision = replay_decision(session, recorded)
    rec, = explain_decisions(session, recorded["observation"], recorded["history"],
                             [decision], removal=removal, step=step)
    rec["episode"] = episode
    rec["recorded_action"] = recorded["action"].tolist()
    rec.update(label_of(action_labels(corpus.action_space), recorded["action"],
                        "recorded_action_label"))
    return [rec], session


def _queries(corpus, source: str, compare: list[str] | None, opened: dict,
             removal) -> list[dict]:
    """``--input``: JSONL queries, each its own decision or the given actions compared."""
    from aoc_cli.control import explain_query, parse_query
    from aoc_cli.control import open_session

    session = open_session(corpus, **opened)
    lines = _read_lines(source)
    if not lines:
        raise AocError("the input holds no queries")
    parsed_compare = [_parse_action(c) for c in compare or []]
    records = []
    for lineno, line in lines:
        obs, hist, action, q_compare = parse_query(line, lineno, corpus,
                                                   session.model.history_length)
        for rec in explain_query(session, obs, hist, action,
                                 compare=parsed_compare or q_compare, removal=removal):
            rec["query"] = lineno
            records.append(rec)
    return records


def _collected_task(corpus) -> str:
    """The built-in task a corpus was collected from ("" for ingested data): its controller
    settings are the defaults, as in ``aoc rollout --env TASK``."""
    tasks = {src.get("task") for src in corpus.manifest.get("sources", [])
             if src.get("kind") == "collect"}
    return tasks.pop() if len(tasks) == 1 else ""


def _parse_action(text: str):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise AocError(f"--compare expects numbers (comma-separated for several dims), got {text!r}") from None
    return values if len(values) > 1 else values[0]


def _read_lines(source: str) -> list[tuple[int, str]]:
    if source == "-":
        text = sys.stdin.read()
    else:
        path = Path(source)
        if not path.is_file():
            raise AocError(f"no such input file: {source}")
        text = path.read_text()
    return [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip()]


def _flat(rec: dict) -> list[dict]:
    """One row per supporting example, with the decision's figures repeated (for CSV)."""
    base = {k: rec.get(k) for k in ("query", "role", "data", "episode", "step", "action",
                                     "action_label", "value", "residual", "support_episodes")
            if k in rec}
    if "what_if" in rec:
        base.update({f"what_if_{k}": rec["what_if"][k] for k in ("action", "value", "residual")})
    rows = []
    for s in rec["support"]:
        row = dict(base)
        row.update({f"support_{k}": v for k, v in s.items() if k not in ("tags", "attribution")})
        if "attribution" in s:
            row["support_projection"] = s["attribution"]["projection"]
        row.update({f"tag_{k}": v for k, v in s["tags"].items()})
        rows.append(row)
    return rows


def _print(records: list[dict], fmt: str) -> None:
    if fmt == "json":
        write_object({"decisions": records}, "json") if len(records) > 1 else \
            write_object(records[0], "json")
    elif fmt == "jsonl":
        for rec in records:
            write_object(rec, "jsonl")
    elif fmt == "csv":
        write_records([row for rec in records for row in _flat(rec)], "csv")
    else:
        from aoc_cli.report import console

        for rec in records:
            typical = rec.get("typical_residual")
            head = {"action": rec["action"], **({"action label": rec["action_label"]}
                                                  if "action_label" in rec else {}),
                    "value (v_hat)": rec["value"], "residual": rec["residual"],
                    "support (episodes)": rec.get("support_episodes")}
            if typical:
                head["typical residual"] = typical
                head["residual / typical"] = rec["residual"] / typical if typical else None
            if "candidates" in rec:
                c = rec["candidates"]
                head["candidates passed"] = f"{c['passed']} of {c['count']}"
                head["best rejected v_hat"] = c["best_rejected_value"]
            for key in ("recorded_action", "logged_action"):
                if key in rec:
                    head[key.replace("_", " ")] = rec[key]
                if f"{key}_label" in rec:
                    head[f"{key.replace('_', ' ')} label"] = rec[f"{key}_label"]
            where = f"{rec['data']} " if "data" in rec else ""
            title = rec.get("role", "decision") + \
                (f" (query {rec['query']})" if "query" in rec else "") + \
                (f" ({where}episode {rec['episode']}"
                 + (f" '{rec['episode_id']}'" if rec.get("episode_id") is not None else "")
                 + f", step {rec['step']})"
                 if "episode" in rec else "")
            write_object(head, "table", title=title)
            write_records(_support_rows(rec["support"]), "table", title="minimal corpus subset")
            for w in rec["warnings"]:
                console.print(f"[yellow]warning:[/] {w}")
            if rec.get("contrast"):
                _print_contrast(rec["contrast"])
            if "what_if" in rec:
                _print_what_if(rec["what_if"])


def _print_contrast(c: dict) -> None:
    """The best action not chosen: its figures, why it lost, its own supporting rows."""
    head = {"action": c["action"], "value (v_hat)": c["value"], "residual": c["residual"],
            "why it lost": c["why"]["text"]}
    if "score" in c:
        head["score"] = c["score"]
    write_object(head, "table", title="contrast: the best action not chosen")
    if c["support"]:
        write_records(_support_rows(c["support"]), "table", title="its supporting rows")


def _support_rows(support: list[dict]) -> list[dict]:
    return [{"row": s["row"], "episode": s["episode"],
             **({"episode_id": s["episode_id"]} if s.get("episode_id") is not None else {}),
             "step": s["step"], **s["tags"], "action": s["action"],
             **({"action label": s["action_label"]} if "action_label" in s else {}),
             "value": s["value"], "weight": s["weight"], "distance": s["distance"],
             "episodes here": s.get("episodes_here")} for s in support]


def _print_what_if(w: dict) -> None:
    """The what-if of one decision as two tables: the decision again, its new subset."""
    head = {"without": f"{w['without']['label']} ({w['without']['rows']} rows, "
                       f"{w['without']['episodes']} episodes)",
            "action": w["action"], "action changed": w["action_changed"],
            "value (v_hat)": w["value"], "value change": w["value_change"],
            "residual": w["residual"], "residual change": w["residual_change"],
            "supporting rows removed": len(w["support_removed"]),
            "unchanged": w["unchanged"]}
    write_object(head, "table", title="what if")
    write_records(_support_rows(w["support"]), "table",
                  title="minimal corpus subset without them")
