"""The accountable controller: candidates, the decision rule, decision records, OOD monitor,
rollouts and the audit log (the decision's explanation is :mod:`aoc_cli.explanation`'s).

Names are imported lazily (PEP 562), so that reading the controller's settings
(:mod:`aoc_cli.control.config`, as every CLI start does for its help) imports neither FAISS
nor the environments. (Hence no submodule is named after a name it gives: importing a
submodule binds its name in the package; the episode loop is ``episodes.py``, the
``rollout`` function ``run.py``'s.)
"""

from __future__ import annotations

from aoc_cli.lazy import exports

_WHERE = {
    "Controller": "controller",
    "ControllerConfig": "config",
    "Decision": "controller",
    "EpisodeResult": "episodes",
    "HistoryBuffer": "episodes",
    "ModelFreeSession": "session",
    "OODMonitor": "monitor",
    "Session": "session",
    "decision_record": "records",
    "flags_against": "monitor",
    "given_settings": "config",
    "model_controller": "session",
    "model_free_session": "session",
    "open_session": "session",
    "read_audit_step": "audit",
    "reference_band": "monitor",
    "rollout": "run",
    "run_episode": "episodes",
    "summarize": "episodes",
    "write_audit": "audit",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
