"""medkit-learn's ward simulator as a log source (aoc_cli.envs.medkit_ward): its weight files
read without unpickling, sampled as medkit samples, and written as a reward-free clinical log."""

from importlib import metadata

import numpy as np
import pytest

from aoc_cli.envs import medkit_ward
from aoc_cli.errors import AocError


def _installed() -> bool:
    try:
        return metadata.distribution(medkit_ward.DISTRIBUTION).version == medkit_ward.VERSION
    except metadata.PackageNotFoundError:
        return False


needs_medkit = pytest.mark.skipif(
    not _installed(), reason="medkit-learn 0.1.0 (the optional medkit extra, installed by "
                             "`make install`) is absent: pip install -e '.[medkit]'")


@needs_medkit
def test_weights_are_read_with_weights_only_and_fill_every_parameter(monkeypatch):
    import torch

    calls = []
    load = torch.load

    def recording(*args, **kwargs):
        calls.append(kwargs.get("weights_only"))
        return load(*args, **kwargs)

    monkeypatch.setattr(torch, "load", recording)
    init, env, pol = medkit_ward._nets(medkit_ward.weight_files())
    assert calls == [True, True, True]
    # strict loading filled the nn.LSTM of each from its standard keys
    assert env.lstm.input_size == 35 + 2 + 49 and pol.lstm.hidden_size == 64
    assert not any(k.startswith("lstm.layers") for k in env.state_dict())


@needs_medkit
def test_stays_follow_the_policy_and_the_end_of_stay_rate():
    import torch
    import torch.nn.functional as F

    sim = medkit_ward.simulate(1500, seed=3, max_length=10)
    lengths, series, actions = sim["lengths"], sim["series"], sim["actions"]
    assert lengths.min() >= 1 and lengths.max() == 10
    # a stay reaches its 10th review when none of the first 9 ended it
    full = np.mean(lengths == 10)
    assert abs(full - (1 - medkit_ward.TERMINATE) ** 9) < 0.04
    # every action is the policy's argmax over the reviews so far, recomputed in one pass
    _init, _env, pol = medkit_ward._nets(medkit_ward.weight_files())
    with torch.no_grad():
        out, _ = pol.lstm(torch.tensor(series, dtype=torch.float32))
        h = out
        for layer in pol.linears:
            h = F.elu(layer(h))
        again = pol.fc(h).argmax(-1).numpy()
    mask = np.arange(10)[None, :] < lengths[:, None]
    assert np.array_equal(again[mask], actions[mask])
    treated = actions[mask].mean()
    assert 0.002 < treated < 0.05           # oxygen is rare in medkit's ward (~1% of steps)
    # the binary features are 0/1, the continuous ones scaled (about mean 0, std 1)
    assert set(np.unique(series[mask][:, 20:])) <= {0.0, 1.0}
    assert abs(series[mask][:, :20].mean()) < 0.3


@needs_medkit
def test_log_is_a_reward_free_clinical_log_reproducible_by_seed():
    a = medkit_ward.collect_data(60, seed=1)
    b = medkit_ward.collect_data(60, seed=1)
    c = medkit_ward.collect_data(60, seed=2)
    assert a.n_episodes == 60 and a.rewards is None and a.discrete
    assert a.observations.shape[1] == 35 + 49
    np.testing.assert_array_equal(a.observations, b.observations)
    assert a.observations.shape != c.observations.shape or not np.array_equal(
        a.observations, c.observations)
    assert a.source["distribution"] == "medkit-learn==0.1.0"


def test_missing_distribution_is_one_line(monkeypatch):
    def absent(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "distribution", absent)
    with pytest.raises(medkit_ward.MedkitMissing) as err:
        medkit_ward.weight_files()
    assert "pip install -e '.[medkit]'" in str(err.value) and "\n" not in str(err.value)
    assert isinstance(err.value, AocError)


def test_unknown_source_and_source_elsewhere_are_one_line(aoc, tmp_path):
    code, _out, err = aoc("bench", "ward", "--tiny", "--source", "mimic",
                          "--out", str(tmp_path / "o"), "--bench-store", str(tmp_path / "s"))
    assert code == 2 and "mimic" in err and "ward or medkit" in err
    assert len(err.strip().splitlines()) == 1
    code, _out, err = aoc("bench", "pendulum-het", "--tiny", "--source", "medkit",
                          "--out", str(tmp_path / "o2"))
    assert code == 2 and "--source" in err and len(err.strip().splitlines()) == 1


def test_ward_sizes_are_one_count_of_patients(aoc, tmp_path):
    for sizes in ("100,200", "10"):
        code, out, err = aoc("bench", "ward", "--tiny", "--sizes", sizes, "--out",
                             str(tmp_path / "o"), "--bench-store", str(tmp_path / "s"))
        assert code == 2 and out == "" and "--sizes" in err and "patients" in err, err
        assert len(err.strip().splitlines()) == 1
