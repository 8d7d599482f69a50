"""Settings several stages share, each declared once.

``SMALL_LOG_ROWS``: a log of at most this many rows is *small*. Three choices change there,
each measured on both sides of the bound:

* the training settings (history length, hidden units, weight decay) of a model imitating
  discrete actions are chosen by validation on held-out episodes (:mod:`aoc_cli.belief.select`;
  never for a value model: a value loss does not track decisions); above it, the paper's;
* an imitation index of discrete actions takes the nearest rows of each action
  (:func:`aoc_cli.corpus_index.neighbours`; ward at 5k rows: AUC 0.939 -> 0.962; at 100k rows
  no AUC gain and 0.7 points of accuracy lost);
* ``aoc evaluate`` searches the index exactly; above it, an IVF structure built for the run
  (exact search of every held-out step against a large corpus costs ~0.5 ms a step, IVF
  ~0.06 ms with a recall of the k nearest of 0.99999 on ward's beliefs: docs/benchmarks.md).
"""

#: The largest log (rows) treated as small (module docstring).
SMALL_LOG_ROWS = 20_000
