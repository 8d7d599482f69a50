"""The command line's line for each library error and warning: flags for parameters, the
``aoc ...`` command that fixes it (aoc_cli.cli.errors)."""

import warnings

import pytest

from aoc_cli.cli.errors import message, showing_warnings
from aoc_cli.errors import (AocError, AocWarning, BadSetting, CorpusExists, CorpusNotFound,
                            Damaged, IndexMissing, IndexStale, Locked, ModelExists, ModelMissing,
                            ModelStale, call, param, warn)


@pytest.mark.parametrize("err,line", [
    (CorpusNotFound("c", "/s", ["a", "b"]),
     "no corpus 'c' in store /s (known: a, b); create it with `aoc ingest` or `aoc collect`"),
    (CorpusExists("c"),
     "corpus 'c' already exists: pass --overwrite to replace it or --append to add to it"),
    (Damaged("c", "/s/c/manifest.json is missing"),
     "corpus 'c' is damaged: /s/c/manifest.json is missing; run `aoc verify c` to see every "
     "damaged file, then re-ingest or re-collect it with --overwrite"),
    (ModelMissing("c", None), "corpus 'c' has no trained model: run `aoc train c`"),
    (ModelMissing("c", "m", ["a"]),
     "corpus 'c' has no model 'm' (models: a): run `aoc train c --model m`"),
    (ModelMissing("c", "bc", why="the sampler needs an imitation-mode model", mode="imitation"),
     "the sampler needs an imitation-mode model: run `aoc train c --model bc --mode imitation`"),
    (ModelExists("c", "m"), "model 'm' of corpus 'c' already exists: pass --overwrite to "
     "replace it, or choose another --model"),
    (ModelStale("c", "m", "a" * 64, "b" * 64),
     f"model 'm' was trained on a different version of corpus 'c' (hash {'a' * 12}, now "
     f"{'b' * 12}): re-run `aoc train c --model m --overwrite`"),
    (IndexMissing("c", "m", "default"),
     "no index 'default' for model 'm' of corpus 'c': run `aoc index c --model m`"),
    (IndexMissing("c", "m", "half"),
     "no index 'half' for model 'm' of corpus 'c': run `aoc index c --model m --index-id half "
     "(with its --episode-rate)`"),
    (IndexStale("c", "m", "default", {"model": "x"}, {"model": "y"}),
     "index 'default' was built from another version of corpus 'c' or model 'm': rebuild it "
     "with `aoc index c --model m`"),
    (BadSetting("residual_cap", 0, f"{param('residual_cap')} must be > 0, got 0"),
     "--residual-cap must be > 0, got 0"),
    (BadSetting("max_epochs", 0, f"{param('max_epochs')} must be >= 1, got 0"),
     "--epochs must be >= 1, got 0"),
    (BadSetting("gamma", 1.5, f"{param('gamma')} must be in [0, 1] for {param('value', 'fqe')}, "
                "got 1.5"), "--gamma must be in [0, 1] for --value fqe, got 1.5"),
    (BadSetting("belief", "critic", f"{param('belief', 'critic')} needs "
                f"{param('mode', 'value')}"), "--belief critic needs --mode value"),
    (Locked("corpus 'c'", [12]), "corpus 'c' is being written by pid 12: wait until it has "
     "finished, then run this again"),
    (AocError("epsilon must be in (0, 1]", "epsilon"), "--epsilon must be in (0, 1]"),
    (AocError(f"re-run `{call('train', 'c', model='m', overwrite=True)}`"),
     "re-run `aoc train c --model m --overwrite`"),
    (AocError(f"build it first ({call('build_index')})"), "build it first (aoc index)"),
])
def test_each_typed_error_is_one_line_with_flags_and_the_command_that_fixes_it(err, line):
    assert message(err) == line
    assert "--" not in str(err) and "aoc " not in str(err)  # the library's own text


def test_a_library_error_on_the_command_line_is_the_line_and_exit_code_2(store, aoc_inproc):
    code, out, err = aoc_inproc("info", "nope")
    assert (code, out) == (2, "")
    assert err == (f"aoc: error: no corpus 'nope' in store {store} (known: none); create it "
                   "with `aoc ingest` or `aoc collect`\n")


def test_debug_shows_the_typed_error_itself(store, aoc_inproc):
    with pytest.raises(CorpusNotFound) as err:
        aoc_inproc("--debug", "info", "nope")
    assert err.value.name == "nope"


def test_a_library_warning_is_one_line_each_time_it_is_given(capsys):
    with showing_warnings():
        for _ in range(2):
            warn(f"{param('append', True)}: corpus 'x' does not exist; creating it")
    assert capsys.readouterr().err == \
        "aoc: warning: --append: corpus 'x' does not exist; creating it\n" * 2
    with warnings.catch_warnings(record=True) as seen:  # outside: the library's text
        warnings.simplefilter("always")
        warn(f"{param('append', True)}: creating it")
    assert str(seen[0].message) == "append=True: creating it"


def test_other_warnings_go_where_they_went_before(capsys):
    with pytest.warns(DeprecationWarning, match="old"):  # the handler before: pytest's record
        with showing_warnings():
            warnings.warn("old", DeprecationWarning)
            warnings.warn(AocWarning("plain"))
    assert capsys.readouterr().err == "aoc: warning: plain\n"
