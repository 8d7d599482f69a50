"""The paper's ward data source: medkit-learn's ward simulator, learned from real ward data.

The paper's ward experiment drew its log from ``medkit-learn`` (0.1.0; Chan et al. 2021), which
ships, inside its wheel, networks fitted to a real hospital ward's records: a VAE of a
patient's admission (49 static covariates: age, then 48 binary ones; the first review's 35
temporal ones: 20 continuous vitals and labs, then 15 binary oxygen devices), a sequential VAE
of the next review given the last one, the treatment and the static covariates, and an LSTM
clinician policy that decides the binary oxygen action (nasal cannula) from the reviews so far.
Everything is in medkit's own scaled units (z-scored continuous features).

The package itself cannot be imported here: its modules import ``gym``, ``pkg_resources`` and
``opacus`` (whose LSTM has changed since), and it loads its weights by unpickling
(``torch.load`` without ``weights_only``). So this module reads only the three weight files
of the installed distribution (located through its metadata, without importing it), each with
``torch.load(..., weights_only=True)``, into plain ``torch.nn`` modules of the same shapes, and
samples as medkit's ``batch_generate`` (domain Ward, environment SVAE, policy LSTM, 2 actions,
the policy's argmax): admission from the VAE's prior, then per review the clinician's action,
the next latent from the transition LSTM and the review from the decoder, the stay ending with
medkit's ward probability :data:`TERMINATE` a review or at ``max_length`` reviews. One
correction, documented: medkit's ``SVAEEnv.step`` feeds the transition LSTM the previous
*latent* (10 features, 61 inputs in all), which cannot run against the LSTM's 86 inputs; the
network was trained (``SVAE_env.loss``) on the previous *review* (35 features) with the action
and the static covariates, and that is what it is given here.

Hand-written because no library samples from these weights without the package's own code.
Install: ``pip install -e '.[medkit]'`` (only the weight files are read).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from aoc_cli.envs.base import Progress
from aoc_cli.envs.ward import write_table  # the same CSV writer as the ward task
from aoc_cli.errors import AocError, BadSetting, param
from aoc_cli.formats import ReadOptions, read_dataset
from aoc_cli.store import CorpusData
from aoc_cli.threads import one_thread

DISTRIBUTION, VERSION = "medkit-learn", "0.1.0"
#: The weight files read, inside the installed distribution.
FILES = {"initialiser": "medkit/initialisers/saved_models/ward_VAE.pth",
         "environment": "medkit/environments/saved_models/ward_2_SVAE.pth",
         "policy": "medkit/policies/saved_models/ward_2_lstm.pth"}
#: medkit's ward domain: the end of a stay's probability at each review.
TERMINATE = 0.0291
LATENT, N_CON, N_BIN, N_STATIC = 10, 20, 15, 49
N_SERIES = N_CON + N_BIN
#: medkit's ward feature names (domains/ward.py), in its order.
SERIES_NAMES = (
    "Best Motor Response", "Best Verbal Response", "CHLORIDE", "CREATINEINE", "DBP",
    "Eye Opening", "GLUCLOSE", "Glasgow Coma Scale Score", "HEMOGLOBIN", "PLATELET COUNT",
    "POTASSIUM", "Pulse", "Respiratory Rate", "SBP", "SODIUM", "SpO2", "TOTAL CO2",
    "Temperature", "UREA NITROGEN", "WHITE BLOOD CELL COUNT", "O2 Device: Aerosol mask",
    "O2 Device: Blow-by", "O2 Device: Continuous Inhaled Medication", "O2 Device: Face tent",
    "O2 Device: Heliox", "O2 Device: CPAP", "O2 Device: Trach Collar",
    "O2 Device: Non-rebreather mask", "O2 Device: None (Room air)", "O2 Device: Other (Comment)",
    "O2 Device: Partial rebreather mask", "O2 Device: Trach", "O2 Device: Bi-PAP",
    "O2 Device: Transtracheal catheter", "O2 Device: Venturi mask")
STATIC_NAMES = ("age",) + tuple(f"static_{i:02d}" for i in range(1, N_STATIC))
ACTION = "act_nasal_cannula"
#: Reviews per stay at most (the held-back ward log's ~10 reviews a patient).
DEFAULT_MAX_LENGTH = 10


class MedkitMissing(AocError):
    """The optional medkit-learn distribution (its weight files) is not installed."""


def weight_files() -> dict[str, Path]:
    """The installed distribution's three weight files (not importing the package)."""
    from importlib import metadata

    try:
        dist = metadata.distribution(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        raise MedkitMissing(f"the medkit source needs {DISTRIBUTION}=={VERSION} (its weight "
                            "files only): pip install -e '.[medkit]'") from None
    if dist.version != VERSION:
        raise MedkitMissing(f"the medkit source reads {DISTRIBUTION}=={VERSION}'s weights; "
                            f"{dist.version} is installed")
    out = {k: Path(dist.locate_file(v)) for k, v in FILES.items()}
    missing = [str(p) for p in out.values() if not p.is_file()]
    if missing:
        raise MedkitMissing(f"{DISTRIBUTION} is installed without its weight files: "
                            + ", ".join(missing))
    return out


def _state(path: Path) -> dict:
    """A state dict read without unpickling, less the old opacus LSTM's copies of the
    ``nn.LSTM`` weights (``lstm.layers.L.cell.{ih,hh}.*``: checked equal, then dropped)."""
    import torch  # lazy: torch, only for the medkit source

    state = torch.load(path, map_location="cpu", weights_only=True)
    out = {}
    for key, value in state.items():
        if ".layers." in key and key.startswith("lstm."):
            _l, _layers, layer, _cell, gate, kind = key.split(".")
            twin = state.get(f"lstm.{kind}_{gate}_l{layer}")
            if twin is None or not torch.equal(twin, value):
                raise AocError(f"{path.name}: {key} has no equal nn.LSTM weight")
            continue
        out[key] = value
    return out


def _nets(files: dict[str, Path]):
    """(initialiser VAE, environment, policy) as torch modules with medkit's weights."""
    from torch import nn  # lazy: torch, only for the medkit source

    def linears(spec: dict[str, tuple[int, int]]) -> nn.ModuleDict:
        return nn.ModuleDict({k: nn.Linear(i, o) for k, (i, o) in spec.items()})

    init = nn.Module()
    init.decoder = linears({"linear1": (LATENT, 100), "linear2": (100, 100),
                            "series_cont_mean": (100, N_CON), "series_cont_lstd": (100, N_CON),
                            "series_bin": (100, N_BIN), "static_cont_mean": (100, 1),
                            "static_cont_lstd": (100, 1), "static_bin": (100, N_STATIC - 1)})
    init.encoder = linears({"linear1": (N_STATIC + N_SERIES, 100), "linear2": (100, 100),
                            "mean_head": (100, LATENT), "lstd_head": (100, LATENT)})
    env = nn.Module()
    env.encoder = linears({"linear1": (N_SERIES, 128), "mean_head": (128, LATENT),
                           "lstd_head": (128, LATENT)})
    env.encoder.linears = nn.ModuleList([nn.Linear(128, 128)])
    env.decoder = linears({"linear1": (LATENT, 128), "series_cont_mean": (128, N_CON),
                           "series_cont_lstd": (128, N_CON), "series_bin": (128, N_BIN)})
    env.decoder.linears = nn.ModuleList([nn.Linear(128, 128)])
    env.lstm = nn.LSTM(N_SERIES + 2 + N_STATIC, 128, 2, batch_first=True)
    env.fc_mean, env.fc_std = nn.Linear(128, LATENT), nn.Linear(128, LATENT)
    pol = nn.Module()
    pol.lstm = nn.LSTM(N_SERIES, 64, 1, batch_first=True)
    pol.linears = nn.ModuleList([nn.Linear(64, 64), nn.Linear(64, 64)])
    pol.fc = nn.Linear(64, 2)
    for net, key in ((init, "initialiser"), (env, "environment"), (pol, "policy")):
        net.load_state_dict(_state(files[key]), strict=True)
        net.eval()
    return init, env, pol


def simulate(n: int, seed: int, max_length: int = DEFAULT_MAX_LENGTH,
             progress: Progress | None = None) -> dict:
    """``n`` stays as medkit's ward simulator draws them: ``static`` (n, 49), ``series``
    (n, T, 35), ``actions`` (n, T) int, ``lengths`` (n,) (1 to ``max_length`` reviews)."""
    import torch  # lazy: torch, only for the medkit source
    import torch.nn.functional as F

    with one_thread(), torch.no_grad():
        init, env, pol = _nets(weight_files())
        gen = torch.Generator().manual_seed(int(seed))

        def normal(mean, lstd):
            return mean + torch.exp(lstd) * torch.randn(mean.shape, generator=gen)

        def bernoulli(p):
            return (torch.rand(p.shape, generator=gen) < p).float()

        def decode_review(dec, z, act):
            h = z
            for layer in [dec["linear1"], *getattr(dec, "linears", [])]:
                h = act(layer(h))
            return h

        # admission: the initialiser VAE's prior, decoded (medkit VAEInit.sample)
        d = init.decoder
        h = F.elu(d["linear2"](F.elu(d["linear1"](torch.randn((n, LATENT), generator=gen)))))
        review = torch.cat([normal(d["series_cont_mean"](h), d["series_cont_lstd"](h)),
                            bernoulli(torch.sigmoid(d["series_bin"](h)))], 1)
        static = torch.cat([normal(d["static_cont_mean"](h), d["static_cont_lstd"](h)),
                            bernoulli(torch.sigmoid(d["static_bin"](h)))], 1)
        series = torch.zeros((n, max_length, N_SERIES))
        actions = torch.zeros((n, max_length), dtype=torch.int64)
        lengths = torch.full((n,), max_length, dtype=torch.int64)
        alive = torch.ones(n, dtype=torch.bool)
        env_state = pol_state = None
        for t in range(max_length):
            series[:, t] = review
            out, pol_state = pol.lstm(review[:, None], pol_state)   # the policy reads the
            h = out[:, -1]                                            # reviews so far
            for layer in pol.linears:
                h = F.elu(layer(h))
            action = pol.fc(h).argmax(1)
            actions[:, t] = action
            done = (torch.rand(n, generator=gen) < TERMINATE) & alive
            lengths[done] = t + 1
            alive &= ~done
            if t + 1 == max_length or not alive.any():
                break
            x = torch.cat([review, F.one_hot(action, 2).float(), static], 1)[:, None]
            out, env_state = env.lstm(x, env_state)
            z = normal(env.fc_mean(out[:, -1]), env.fc_std(out[:, -1]))
            h = decode_review(env.decoder, z, torch.sigmoid)
            review = torch.cat([normal(env.decoder["series_cont_mean"](h),
                                       env.decoder["series_cont_lstd"](h)),
                                bernoulli(torch.sigmoid(env.decoder["series_bin"](h)))], 1)
            if progress is not None:
                progress(t + 1, max_length)
    return {"static": static.numpy().astype(np.float64),
            "series": series.numpy().astype(np.float64),
            "actions": actions.numpy(), "lengths": lengths.numpy()}


def _name(text: str) -> str:
    return "obs_" + "".join(c if c.isalnum() else "_" for c in text.lower()).strip("_")


def collect_data(episodes: int, seed: int = 0, max_length: int = DEFAULT_MAX_LENGTH,
                 progress: Progress | None = None) -> CorpusData:
    """``episodes`` stays from medkit's ward simulator, written as the two CSV files of a
    clinical log (steps; static covariates) and read back as ``aoc ingest --static`` reads
    them (reward-free, discrete actions)."""
    if episodes <= 0:
        raise BadSetting("episodes", episodes,
                         f"{param('episodes')} must be a positive integer, got {episodes}")
    if max_length < 1:
        raise BadSetting("max_length", max_length,
                         f"{param('max_length')} must be a positive integer, got {max_length}")
    sim = simulate(int(episodes), int(seed), int(max_length), progress)
    lengths = sim["lengths"]
    mask = np.arange(sim["series"].shape[1])[None, :] < lengths[:, None]
    pat, hour = np.nonzero(mask)
    ids = np.array([f"m{i:05d}" for i in range(int(episodes))])
    rows = {"patient": ids[pat], "hour": hour}
    for j, name in enumerate(SERIES_NAMES):
        rows[_name(name)] = sim["series"][pat, hour, j]
    rows[ACTION] = sim["actions"][pat, hour]
    static = {"patient": ids}
    for j, name in enumerate(STATIC_NAMES):
        static[name] = sim["static"][:, j]
    with tempfile.TemporaryDirectory(prefix=".aoc-medkit-") as tmp:
        steps, stat = Path(tmp) / "medkit.csv", Path(tmp) / "medkit-static.csv"
        write_table(steps, rows)
        write_table(stat, static)
        data = read_dataset(steps, options=ReadOptions(
            id_column="patient", time_column="hour", static=stat, discrete_actions=True,
            reward_free=True))
    data.source = {"kind": "medkit", "distribution": f"{DISTRIBUTION}=={VERSION}",
                   "simulator": "ward SVAE, LSTM policy", "episodes": int(episodes),
                   "seed": int(seed), "max_length": int(max_length)}
    return data
