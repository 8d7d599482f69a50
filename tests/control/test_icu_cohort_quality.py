"""The cohort test bed end to end (aoc_cli/envs/icu_cohort.py): 10,000 stays drawn from the
ICU-Sepsis MDP written as a cohort CSV with noisy features (sd 0.3), 15% empty cells and 3%
of the stays cut short, ingested with the clinical guide's command, ``aoc train`` and ``aoc
index`` with no flag, and AOC rolled out in the same MDP through the same noise: its true
survival.

Guards the cohort's promise and its goal: on noisy features, where no observation repeats,
AOC (rule 7: rule 2 over the log's rows near the step's denoised observation, do no harm;
docs/design.md, "Settings from the log's evidence") is never below the clinicians it learned
from by more than 0.005, shown above them, and at least 0.81, as on exact states: measured
0.8126 [0.8072, 0.8181] over 20,000 episodes, the clinicians 0.7818 exact, their likely dose
(what rule 7 keeps) on the same patients 0.7897, and shown above the clinicians' modal dose
read through the nearest state centre on the same patients (docs/results/icu-cohort.md).
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from aoc_cli import open_session
from aoc_cli.control.batch import BatchPolicy
from aoc_cli.envs import icu_cohort, icu_sepsis

pytestmark = pytest.mark.quality

ROOT = Path(__file__).resolve().parents[2]
STAYS, NOISE, EPISODES = 10_000, 0.3, 10_000
#: "Never below the clinicians by more than 0.005" (their exact survival).
MARGIN = 0.005
#: The goal at noise 0.3 and 10k stays: as on exact states.
GOAL = 0.81


@pytest.fixture(scope="module")
def cohort(tmp_path_factory):
    from tests.conftest import run_aoc

    tmp = tmp_path_factory.mktemp("cohort")
    csv = tmp / "cohort.csv"
    subprocess.run([sys.executable, str(ROOT / "scripts" / "icu_cohort.py"), str(csv),
                    "--stays", str(STAYS), "--noise", str(NOISE), "--seed", "0"], check=True,
                   capture_output=True)
    env = {**os.environ, "AOC_STORE": str(tmp / "store")}
    for args in (("ingest", str(csv), "--name", "c", "--discrete-actions", "--impute", "hold",
                  "--outcome", "died_in_hosp", "--outcome-reward", "1=0,0=1"),
                 ("train", "c", "--threads", "1"), ("index", "c")):
        code, _out, err = run_aoc(*args, "--format", "json", env=env)
        assert code == 0, (args, err)
    return open_session("c", store=tmp / "store")


def test_aoc_on_a_noisy_cohort_is_never_worse_than_the_clinicians(cohort):
    ctl = cohort.controller
    assert ctl.do_no_harm and ctl.config.support_penalty is None   # no exact repeats here
    assert ctl.model.config.value == "neighbours"                  # rule 7's values
    assert ctl.neighbourhood.masked is not None          # the held cells left out (the gaps)
    result = icu_cohort.rollout_value(BatchPolicy(ctl), EPISODES, noise=NOISE, seed=1)
    clinicians = icu_cohort.clinicians_value()
    # 10,000 episodes measure a survival to +- 0.008 (the suite's time; the results' 20,000:
    # +- 0.006): never below the clinicians by more than the margin, and above them (measured
    # over 20,000: 0.8126 [0.8072, 0.8181] against 0.7818)
    assert result["low"] >= clinicians - MARGIN, (result, clinicians)
    assert result["low"] > clinicians, (result, clinicians)
    assert result["value"] >= GOAL, result          # the goal at noise 0.3, 10k stays
    # on the same patients (common random numbers), against the clinicians' modal dose in the
    # state whose centre is nearest (what they most often give there, read as the features
    # allow: 0.7898 over 20,000, where rule 7's likely dose, the one it keeps, read 0.7897;
    # a state policy, so its rollout costs seconds): not shown worse by the margin, and
    # shown better (measured +0.022 [0.016, 0.028] on the bench's 20,000; on these 10,000
    # +0.0176 [0.0093, 0.0259], AOC 0.8111, the modal dose 0.7935)
    modal = icu_cohort.rollout_value(
        icu_cohort.nearest_centre_policy(icu_sepsis.tables("mean").modal()), EPISODES,
        noise=NOISE, seed=1)
    paired = icu_cohort.paired_difference(result["survived"], modal["survived"])
    assert paired["low"] > -MARGIN, paired
    assert paired["low"] > 0, paired


def test_the_value_belief_learns_on_noisy_features(cohort):
    """Its targets, FQE over the log's neighbourhoods, are what the log says near an
    observation: the belief fits them where it fitted one stay's return at R^2 0.01."""
    metrics = cohort.controller.model.meta["metrics"]
    assert metrics["val_r2"] > 0.5, metrics["val_r2"]       # measured 0.710 (best epoch 13)
