"""The accountable controller: candidates, decisions, decision records, OOD monitor, rollouts."""

from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.controller import Controller, Decision
from aoc_cli.control.monitor import OODMonitor, flags_against, reference_band
from aoc_cli.control.records import decision_record, read_audit_step, write_audit
from aoc_cli.control.rollout import EpisodeResult, HistoryBuffer, run_episode, summarize
from aoc_cli.control.run import (
    explain_logged_step,
    explain_query,
    parse_query,
    replay_decision,
    rollout,
)
from aoc_cli.control.session import ModelFreeSession, Session, model_free_session, open_session

__all__ = [
    "Controller",
    "ControllerConfig",
    "Decision",
    "EpisodeResult",
    "HistoryBuffer",
    "ModelFreeSession",
    "OODMonitor",
    "Session",
    "decision_record",
    "explain_logged_step",
    "explain_query",
    "flags_against",
    "model_free_session",
    "open_session",
    "parse_query",
    "read_audit_step",
    "reference_band",
    "replay_decision",
    "rollout",
    "run_episode",
    "summarize",
    "write_audit",
]
