"""Which reader a path needs: by content first (HDF5 signature and keys, ZIP signature),
then by name; a path that does not exist may be a Minari dataset id."""

from __future__ import annotations

import os
from pathlib import Path

from aoc_cli.errors import AocError, param
from aoc_cli.formats.common import open_h5
from aoc_cli.formats.d3rlpy import is_d3rlpy
from aoc_cli.formats.minari import data_folder, datasets_root
from aoc_cli.formats.table import PARQUET_MAGIC

FORMATS = ("minari", "d4rl", "d3rlpy", "npz", "csv", "parquet")
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_ZIP_SIGNATURE = b"PK\x03\x04"


def _is_hdf5(path: Path) -> bool:
    """HDF5 signature at offset 0, 512, 1024, ... (after an optional user block)."""
    with open(path, "rb") as fh:
        offset = 0
        while True:
            fh.seek(offset)
            head = fh.read(8)
            if len(head) < 8:
                return False
            if head == _HDF5_SIGNATURE:
                return True
            offset = 512 if offset == 0 else offset * 2


def detect_format(path: str | os.PathLike) -> str:
    """One of :data:`FORMATS` for ``path``; an AocError when it is missing or unknown."""
    p = Path(path)
    if not p.exists():
        if data_folder(path) is not None:
            return "minari"
        raise AocError(f"no such file or folder: {path} (nor a Minari dataset id under "
                       f"{datasets_root()}); check the path")
    if p.is_dir():
        if data_folder(p) is not None:
            return "minari"
        raise AocError(f"{path} is a folder but not a Minari dataset (no main_data.hdf5 and "
                       "metadata.json in it or in its data/): pass a dataset file")
    if p.name == "main_data.hdf5" and data_folder(p) is not None:
        return "minari"
    if _is_hdf5(p):
        with open_h5(p) as f:
            if is_d3rlpy(f):
                return "d3rlpy"
            if "observations" in f and "actions" in f:
                return "d4rl"
            if "episode_0" in f:
                raise AocError(f"{path} looks like a Minari main_data.hdf5 without its "
                               "metadata.json: pass the dataset folder")
            keys = ", ".join(sorted(f.keys())[:8]) or "none"
        raise AocError(f"cannot tell the format of HDF5 file {path} (top-level keys: {keys}): "
                       f"pass {param('fmt', 'd4rl')} or {param('fmt', 'd3rlpy')} if it is one "
                       "of those")
    with open(p, "rb") as fh:
        head = fh.read(4)
    if head == PARQUET_MAGIC or p.suffix.lower() in (".parquet", ".pq"):
        return "parquet"
    if head == _ZIP_SIGNATURE or p.suffix == ".npz":
        return "npz"
    suffixes = [s.lower() for s in p.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes = suffixes[:-1]
    if suffixes and suffixes[-1] in (".csv", ".tsv"):
        return "csv"
    raise AocError(f"cannot tell the format of {path}: pass {param('fmt')} "
                   f"{'|'.join(FORMATS)}")
