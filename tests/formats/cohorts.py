"""The synthetic cohort of scripts/cohort.py (loaded from its file: scripts/ is no package),
small, and the ingest options of its column roles."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("aoc_cohort_script", ROOT / "scripts" / "cohort.py")
script = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(script)

#: A few vitals and labs keep the tests fast; the roles as ``aoc ingest`` flags would set them.
LABS = 6
OBS = ["age", "gender", *(script.VITALS + script.LABS)[:LABS]]


def cohort(stays: int = 40, seed: int = 0, **kw) -> dict:
    return script.cohort(stays, seed, labs=LABS, **kw)


def roles(**extra) -> dict:
    """ReadOptions fields of the cohort's roles (a dict: aoc_cli.ingest takes one)."""
    return {"id_column": "icustayid", "time_column": "bloc", "obs_columns": list(OBS),
            **extra}


def write(cols: dict, path: Path) -> Path:
    return script.write(cols, path)
