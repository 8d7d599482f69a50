"""aoc: accountable offline control.

Every decision is backed by a small, named set of rows of a logged dataset (the decision
corpus), with weights and a corpus residual that says how far the decision had to extrapolate.
The library gives the same functions the ``aoc`` commands call.
"""

__version__ = "0.1.0"

from aoc_cli.errors import AocError  # noqa: E402

__all__ = ["AocError", "__version__"]
