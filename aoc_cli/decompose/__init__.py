"""The decomposition engine: a query belief as a weighted, minimal subset of corpus rows.

`decompose(beliefs, queries, k=None, values=None, index=None, reference=False)` runs the paper's
four steps (neighbours, exact corpus residual and projection, minimal corpus subset, value) for
a whole batch of queries at once; see `engine.py`, which reads top to bottom.
"""

from aoc_cli.decompose.engine import DecomposeConfig, Decomposition, decompose
from aoc_cli.decompose.k_rule import default_k, index_k, per_action_k, rarest_share, subset_size

__all__ = ["DecomposeConfig", "Decomposition", "decompose", "default_k", "index_k",
           "per_action_k", "rarest_share", "subset_size"]
