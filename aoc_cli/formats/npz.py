"""NPZ with the D4RL keys: ``observations``, ``actions``, ``rewards``, ``terminals``,
``timeouts`` (and any other per-row array, usable by ``--tag-column`` or kept as a column).

Read with ``allow_pickle=False``: an archive holding Python objects is refused, never unpickled.
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats.common import ReadOptions, from_flat
from aoc_cli.store import CorpusData

_KNOWN = ("observations", "actions", "rewards", "terminals", "timeouts", "next_observations")


def read_npz(path: Path, options: ReadOptions) -> CorpusData:
    """Read an NPZ archive with the D4RL keys."""
    with open(path, "rb") as fh:
        head = fh.read(6)
    if head[:4] != b"PK\x03\x04" and head != b"\x93NUMPY":
        raise AocError(f"cannot read {path}: not an NPZ archive (no ZIP signature); save it "
                       f"with numpy.savez, or pass {param('fmt')} with its real format")
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise AocError(f"{path} is a single .npy array, not an NPZ archive with the "
                           "D4RL keys (observations, actions, rewards, terminals, timeouts)")
        with z:
            missing = [k for k in ("observations", "actions") if k not in z.files]
            if missing:
                raise AocError(f"{path} has no {', '.join(missing)} (keys: "
                               f"{', '.join(z.files) or 'none'}): save the D4RL keys")
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, OSError, zlib.error) as err:
        raise AocError(f"cannot read {path}: truncated or corrupt NPZ ({err}); re-export "
                       "it") from None
    except ValueError as err:
        text = str(err).splitlines()[0] if str(err) else type(err).__name__
        if "pickle" in text.lower() or "object" in text.lower():
            raise AocError(f"cannot read {path}: {text} (object arrays are refused, never "
                           "unpickled: save plain numeric arrays)") from None
        raise AocError(f"cannot read {path}: a damaged array in the archive ({text}); "
                       "re-export it") from None
    n = len(arrays["observations"])
    extra = {k: v for k, v in arrays.items()
             if k not in _KNOWN and v.ndim >= 1 and
             (k in options.tag_columns or (v.ndim == 1 and v.dtype.kind in "fiub" and len(v) == n))}
    return from_flat(arrays["observations"], arrays["actions"], arrays.get("rewards"),
                     arrays.get("terminals"), arrays.get("timeouts"),
                     {"format": "npz", "path": str(Path(path).resolve())}, options, extra=extra)
