"""The audit log has one home (aoc_cli/control/audit.py): what a rollout records reads back
from it, step by step and episode by episode, and no other module opens its HDF5 file."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from aoc_cli.control import open_session, rollout
from aoc_cli.control.audit import read_audit_episode, read_audit_residuals, read_audit_step
from aoc_cli.envs import make_env
from aoc_cli.errors import AocError

PACKAGE = Path(__file__).resolve().parents[2] / "aoc_cli"
#: The modules that may open HDF5 files: the store, the dataset formats, the training
#: stream over a corpus's columns, and the audit log's one module.
HDF5_HOMES = ("store/", "formats/", "belief/stream.py", "control/audit.py")


def test_a_rollouts_decisions_read_back_from_the_audit_log(small_maze, tmp_path):
    session = open_session(small_maze.corpus("maze"), seed=1)
    path = tmp_path / "a.h5"
    results, _ = rollout(session, make_env("maze", max_episode_steps=12), 2, seed=4,
                         audit=str(path))
    for e, res in enumerate(results):
        got = read_audit_episode(path, e)
        np.testing.assert_array_equal(got.residuals, [d.residual for d in res.decisions])
        np.testing.assert_array_equal(got.actions, [d.action for d in res.decisions])
        np.testing.assert_array_equal(got.ood, res.ood)
        t = len(res.decisions) - 1
        step = read_audit_step(path, e, t)
        np.testing.assert_array_equal(step["support_rows"][step["support_rows"] >= 0],
                                      res.decisions[t].support_rows)
        assert step["meta"]["corpus_hash"] == small_maze.corpus("maze").hash
    _meta, runs = read_audit_residuals(path)
    assert [len(r) for r in runs] == [len(r.decisions) for r in results]
    with pytest.raises(AocError, match=r"no decisions of episode 7 \(episodes: \[0, 1\]\)"):
        read_audit_episode(path, 7)


def test_no_module_but_the_audit_logs_opens_an_hdf5_file():
    opens = re.compile(r"^\s*(import h5py|from h5py)", re.M)
    found = sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py")
                   if opens.search(p.read_text()))
    assert found and all(f.startswith(HDF5_HOMES) for f in found), found
    assert "control/audit.py" in found
