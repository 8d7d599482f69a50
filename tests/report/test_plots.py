"""`aoc rollout --plot`'s curves: one colour per episode named in the legend, OOD flags as
markers."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from aoc_cli.report import plots


def test_rollout_curves_colour_each_episode_and_say_so(monkeypatch, tmp_path):
    shown = {}
    monkeypatch.setattr(plots, "save", lambda fig, path: shown.update(fig=fig))
    episodes = []
    for e in range(2):
        ood = np.zeros(12, bool)
        ood[[5, 9]] = e == 1
        episodes.append(SimpleNamespace(
            episode=e, length=12, rewards=np.arange(12.0), residuals=list(np.linspace(0, 1, 12)),
            ood=ood, monitor=SimpleNamespace(upper=[np.inf] * 3 + [0.5] * 9)))
    plots.plot_rollout_curves(episodes, tmp_path / "x.png")
    ax = shown["fig"].axes[1]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["episode 0", "episode 1", "OOD band (3 sigma, its episode's colour)",
                      "OOD flag"]
    solid = [line for line in ax.get_lines() if line.get_linestyle() == "-"]
    assert len(solid) == 2 and solid[0].get_color() != solid[1].get_color()
    marks = ax.collections[0].get_offsets()
    np.testing.assert_array_equal(np.asarray(marks)[:, 0], [5, 9])
    plots.plt.close(shown["fig"])
