"""The settings dataclasses' one convention (aoc_cli/settings.py): every config is checked when
it is built (also by ``dataclasses.replace``), cannot be changed afterwards, refuses a key that
is no setting, and lets None through only where None means something."""

from __future__ import annotations

import dataclasses

import pytest

from aoc_cli.baselines.mpc import MPCConfig
from aoc_cli.baselines.offline_rl import OfflineRLConfig
from aoc_cli.belief.config import BeliefConfig, FQEConfig
from aoc_cli.control.config import ControllerConfig
from aoc_cli.ope.evaluate_block import OPESettings
from aoc_cli.decompose.engine import DecomposeConfig
from aoc_cli.errors import BadSetting
from aoc_cli.index.search.config import IndexConfig
from aoc_cli.settings import Settings, within

CONFIGS = [BeliefConfig, FQEConfig, ControllerConfig, IndexConfig, DecomposeConfig,
           OPESettings, OfflineRLConfig, MPCConfig]


@pytest.mark.parametrize("cls", CONFIGS, ids=lambda c: c.__name__)
def test_every_config_follows_the_convention(cls):
    assert issubclass(cls, Settings) and cls.__dataclass_params__.frozen
    for item in dataclasses.fields(cls):
        assert item.metadata.get("help"), f"{cls.__name__}.{item.name} has no help"
    default = cls()
    assert cls.from_dict(default.to_dict()) == default
    with pytest.raises(dataclasses.FrozenInstanceError):
        default.seed = 1


def test_an_unknown_key_is_refused_naming_it_and_the_known_ones():
    with pytest.raises(BadSetting) as err:
        IndexConfig.from_dict({"kidn": "hnsw"})
    assert err.value.param == "kidn" and err.value.value == "hnsw"
    assert str(err.value).startswith("unknown index setting kidn: the settings are ")
    assert "kind" in str(err.value).split("the settings are ")[1].split(", ")
    with pytest.raises(BadSetting, match="unknown controller setting epsilom"):
        ControllerConfig.from_dict({"epsilom": 0.3})
    # a saved config of an older aoc: its unknown key ignored, the rest read and checked
    assert IndexConfig.from_dict({"kind": "flat", "retired": 1}, strict=False).kind == "flat"
    with pytest.raises(BadSetting, match="^unknown kind .lsh."):
        IndexConfig.from_dict({"kind": "lsh", "retired": 1}, strict=False)


@pytest.mark.parametrize("build, param, text", [
    (lambda: ControllerConfig(epsilon=0.0), "epsilon", "epsilon must be in (0, 1], got 0.0"),
    (lambda: ControllerConfig(epsilon=float("nan")), "epsilon", "must be in (0, 1], got nan"),
    (lambda: ControllerConfig(k=0), "k", "k must be >= 1, got 0"),
    (lambda: ControllerConfig(sampler="x"), "sampler", "unknown sampler 'x': use uniform or bc"),
    (lambda: IndexConfig(ivf_nprobe=0), "ivf_nprobe", "ivf_nprobe must be >= 1, got 0"),
    (lambda: BeliefConfig(label_smoothing=1.0), "label_smoothing", "must be in [0, 1), got 1.0"),
    (lambda: BeliefConfig(hidden=None), "hidden", "hidden must be given, got None"),
    (lambda: DecomposeConfig(k=0), "k", "k must be >= 1, got 0"),
    (lambda: OPESettings(gamma=1.5), "ope_gamma", "ope_gamma must be in (0, 1], got 1.5"),
    (lambda: OPESettings(fqe_refits=1), "fqe_refits", "must be 0 or at least 2, got 1"),
    (lambda: OfflineRLConfig(steps=0), "steps", "steps must be >= 1, got 0"),
    (lambda: MPCConfig(horizon=0), "horizon", "horizon must be >= 1, got 0"),
    (lambda: FQEConfig(lr=0.0), "lr", "lr must be > 0, got 0.0"),
])
def test_an_out_of_range_value_fails_when_the_config_is_built(build, param, text):
    with pytest.raises(BadSetting) as err:
        build()
    assert err.value.param == param and text in str(err.value)


def test_replace_checks_again_and_cross_field_rules_hold():
    config = ControllerConfig()
    with pytest.raises(BadSetting, match="^epsilon"):
        dataclasses.replace(config, epsilon=2.0)
    assert dataclasses.replace(config, epsilon=0.25).epsilon == 0.25
    with pytest.raises(BadSetting, match="belongs to"):
        BeliefConfig(belief="critic", dynamics_weight=0.5)
    with pytest.raises(BadSetting, match="needs mode='value'"):
        dataclasses.replace(BeliefConfig(), mode="imitation", belief="reward")


def test_none_is_valid_where_it_means_something():
    # None: the index's k, no cap, the critic's own step rule, every core, the default steps
    assert ControllerConfig(k=None, residual_cap=None, min_support=None).k is None
    assert BeliefConfig(critic_steps=None, threads=None).threads is None
    assert OPESettings(fqe_steps=None, propensity=None).fqe_steps is None
    assert DecomposeConfig(k=None).k is None


@pytest.mark.parametrize("value, bounds, inside", [
    (0.0, "(0, 1]", False), (1.0, "(0, 1]", True), (1.0, "[0, 1)", False),
    (0.0, "[0, 1)", True), (1, ">= 1", True), (0, "> 0", False), (float("nan"), ">= 0", False),
])
def test_bounds_read_as_written(value, bounds, inside):
    assert within(value, bounds) is inside
