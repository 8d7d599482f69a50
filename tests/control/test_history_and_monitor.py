"""The control-time history equals the corpus history; the OOD monitor's 3-sigma band."""

import numpy as np
import pytest

from aoc_cli.control import HistoryBuffer, OODMonitor
from aoc_cli.store import gather_history


@pytest.mark.parametrize("length", [0, 1, 4, 7])
@pytest.mark.parametrize("discrete", [False, True])
def test_control_time_history_is_built_exactly_as_in_the_corpus(length, discrete):
    rng = np.random.default_rng(length)
    T, d_o, d_a = 12, 3, 2
    obs = rng.standard_normal((T, d_o)).astype(np.float32)
    act = rng.integers(0, 4, T) if discrete else rng.standard_normal((T, d_a)).astype(np.float32)
    rew = rng.standard_normal(T)
    corpus_h = gather_history(np.arange(T), np.zeros(T, np.int64), length, obs, act, rew)
    buf = HistoryBuffer(length, d_o, d_a, discrete)
    for t in range(T):
        h = buf.history()
        for got, want in zip(h, corpus_h):
            np.testing.assert_array_equal(got[0], want[t])
            assert got.dtype == want.dtype
        buf.push(obs[t], act[t], rew[t])


def test_monitor_flags_a_jump_after_warmup_and_keeps_flagging_a_lasting_shift():
    rng = np.random.default_rng(0)
    m = OODMonitor(warmup=10, sigmas=3.0)
    calm = [m.update(0.1 + 0.01 * x) for x in rng.standard_normal(50)]
    assert not any(calm)
    shifted = [m.update(0.5 + 0.01 * x) for x in rng.standard_normal(5)]
    assert all(shifted)
    # flagged steps stay out of the band, so the band did not widen
    assert m.band() < 0.2


def test_monitor_is_silent_during_warmup_and_never_flags_a_smaller_residual():
    m = OODMonitor(warmup=5)
    assert not any(m.update(x) for x in [0.0, 5.0, 0.1, 9.0, 0.2])
    for _ in range(20):
        m.update(1.0)
    assert m.update(0.0) is False


def test_monitor_floor_keeps_exact_zeros_from_flagging_tiny_residuals():
    m = OODMonitor(warmup=3, floor=1e-3)
    for _ in range(10):
        m.update(0.0)
    assert m.update(1e-9) is False
    assert m.update(1.0) is True


def test_reference_band_is_the_pooled_mean_plus_three_sigma_per_step():
    from aoc_cli.control.monitor import flags_against, reference_band

    rng = np.random.default_rng(0)
    runs = [list(0.01 + 0.001 * rng.standard_normal(30)) for _ in range(4)]
    for r in runs:
        r[12] += 0.05                      # every clean run has a spike at step 12 (a hand-over)
    band = reference_band(runs, window=0)
    col = np.array([r[5] for r in runs])
    assert band[5] == pytest.approx(col.mean() + 3 * col.std(ddof=1))
    assert band[12] > 0.05                 # the spike is part of the reference
    # a run like the clean ones is not flagged, not even at its own spike; a lasting rise is
    clean = list(0.01 + 0.0005 * rng.standard_normal(30))
    clean[12] += 0.05
    assert not flags_against(clean, reference_band(runs)).any()
    shifted = clean[:20] + [0.03] * 10
    assert flags_against(shifted, reference_band(runs))[20:].all()
    # pooling neighbouring steps, a floor and a minimum
    wide = reference_band(runs, window=2, floor=0.01, minimum=0.2)
    assert np.all(wide == 0.2)
    assert flags_against([None, 0.5], np.array([0.1])).tolist() == [False, True]


def test_monitor_with_a_reference_band_flags_from_the_first_step():
    mon = OODMonitor(warmup=10, reference=np.array([0.1, 0.1, 0.5]))
    assert [mon.update(x) for x in (0.2, 0.05, 0.4, 0.6)] == [True, False, False, True]
    assert mon.upper == [0.1, 0.1, 0.5, 0.5]
