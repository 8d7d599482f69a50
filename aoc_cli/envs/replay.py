"""``--behaviour replay``: the data of an agent that starts random and improves, as the paper's
corpora were made (the training replay buffers of TD3: random actions first, then an improving
policy with exploration noise).

No agent is trained: the task's own controller is run with a scripted schedule of its noise.
At a share ``f`` of the collection (of each system's episodes on pendulum-het, of the rows on
lunar), the episode is

* ``f < RANDOM_SHARE`` (the first 10%, as the reference code's 100k random steps of 1M):
  uniformly random actions (label ``random``);
* otherwise the task's controller with its noise process (pendulum-het: i.i.d. Gaussian torque
  noise; lunar: the AR(1) deviation) of std ``1.0 (1 - (f - RANDOM_SHARE) / (1 - RANDOM_SHARE))``,
  falling linearly from 1.0 to 0 (label ``replay-noise<std rounded to 0.1>``).

The same seed gives the same corpus, bit for bit; the exact std of each episode is kept in the
corpus column ``noise_std`` (NaN for the random episodes) beside the ``policy`` tag.
"""

from __future__ import annotations

import numpy as np

BEHAVIOURS = ("mix", "replay")
RANDOM_SHARE = 0.1
START_STD = 1.0
#: The ``policy`` tag's labels of a replay corpus, in order of the schedule.
POLICIES = ("random",) + tuple(f"replay-noise{i / 10:.1f}" for i in range(10, -1, -1))


def noise_at(fraction: float) -> float | None:
    """The noise std at ``fraction`` in [0, 1] of the collection; None: random actions."""
    if fraction < RANDOM_SHARE:
        return None
    return START_STD * max(0.0, 1.0 - (fraction - RANDOM_SHARE) / (1.0 - RANDOM_SHARE))


def label(std: float | None) -> str:
    """The ``policy`` tag of an episode run with noise ``std`` (None: random)."""
    return "random" if std is None else f"replay-noise{round(std, 1):.1f}"


def noise_column(episode_stds, lengths) -> np.ndarray:
    """(N,) float64 per-row noise std (NaN for random episodes) from per-episode values."""
    stds = np.array([np.nan if s is None else s for s in episode_stds], dtype=np.float64)
    return np.repeat(stds, np.asarray(lengths, dtype=np.int64))
