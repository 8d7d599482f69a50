"""aoc: accountable offline control.

Every decision is backed by a small, named set of rows of a logged dataset (the decision
corpus), with weights and a corpus residual that says how far the decision had to extrapolate.
The library gives the same functions the ``aoc`` commands call.
"""

import os as _os

# torch's and FAISS's OpenMP pools busy-wait by default; on a shared 2-core machine that made a
# 2-thread step 30x slower. Set before any of them is imported (a user's setting wins).
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"

from aoc_cli.errors import AocError  # noqa: E402

__all__ = ["AocError", "__version__"]
