"""The library's errors carry data and name parameters, never command-line flags or ``aoc ...``
commands; its warnings go through :mod:`warnings` (aoc_cli.errors)."""

import ast
import json
import pickle
import re
import warnings
from pathlib import Path

import pytest

import aoc_cli
import aoc_cli.errors as errors
from aoc_cli.belief import BeliefConfig, load_model, train_model
from aoc_cli.index import build_index, load_index
from aoc_cli.errors import (AocError, AocWarning, BadSetting, CorpusNotFound, IndexMissing,
                            IndexStale, ModelMissing, call, param)
from aoc_cli.store import Store
from aoc_cli.store.atomic import seal
from tests.belief.corpora import synthetic_value

LIBRARY = Path(aoc_cli.__file__).parent
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
COMMAND = re.compile(r"\baoc (ingest|collect|train|index|explain|evaluate|rollout|bench|info|"
                     r"verify|export)\b")
#: The names a message is made by: the error classes, warn and warnings.warn.
MAKERS = {n for n, v in vars(errors).items()
          if isinstance(v, type) and issubclass(v, (AocError, AocWarning))} | {"warn"}


def library_modules():
    """Every module of the package outside the command line (aoc_cli/cli/)."""
    return [p for p in sorted(LIBRARY.rglob("*.py")) if p.relative_to(LIBRARY).parts[0] != "cli"]


def message_texts(tree: ast.AST):
    """(line, text) of every string constant inside a call that makes an error or a warning."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = getattr(node.func, "id", getattr(node.func, "attr", ""))
            if name in MAKERS:
                for sub in ast.walk(node):
                    if isinstance(sub, ast.Constant) and isinstance(sub.value, str):
                        yield sub.lineno, sub.value


def test_no_library_message_names_a_flag_or_an_aoc_command():
    found = []
    for path in library_modules():
        for line, text in message_texts(ast.parse(path.read_text())):
            if FLAG.search(text) or COMMAND.search(text):
                found.append(f"{path.relative_to(LIBRARY)}:{line}: {text!r}")
    assert found == [], "library messages name flags or commands (use errors.param / call):\n" \
        + "\n".join(found)


def test_every_bad_setting_names_its_setting():
    """``BadSetting(param, value, why)``: ``why`` marks ``param`` (``param('epsilon')``) or
    says its name (``unknown device 'x'``), so the line cannot lose what it is about."""
    found = []
    for path in library_modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.Call) and getattr(node.func, "id", "") == "BadSetting"):
                continue
            name, why = node.args[0], node.args[2]
            marked = [ast.dump(c.args[0]) for c in ast.walk(why) if isinstance(c, ast.Call)
                      and getattr(c.func, "id", "") == "param" and c.args]
            words = " ".join(c.value for c in ast.walk(why)
                             if isinstance(c, ast.Constant) and isinstance(c.value, str))
            names = [name.body, name.orelse] if isinstance(name, ast.IfExp) else [name]
            for one in names:  # ("a" if ... else "b"): both
                said = isinstance(one, ast.Constant) and one.value.replace("_", " ") in words
                if ast.dump(one) not in marked and not said:
                    found.append(f"{path.relative_to(LIBRARY)}:{node.lineno}")
    assert found == []


def test_the_scan_finds_a_flag_and_a_command_in_a_message():
    # the scan above would find what it guards against
    bad = ast.parse('raise AocError(f"--epsilon must be > 0: run `aoc train {x}`")\n'
                    'warn("use --mode imitation")')
    lines = {line for line, t in message_texts(bad) if FLAG.search(t) or COMMAND.search(t)}
    commands = [t for _, t in message_texts(bad) if COMMAND.search(t)]
    assert lines == {1, 2} and commands == ["--epsilon must be > 0: run `aoc train "]


def test_no_library_module_prints():
    """Messages are errors or warnings; data goes through the command line's cli/output.py
    (stdout)."""
    found = []
    for path in library_modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "print":
                found.append(f"{path.relative_to(LIBRARY)}:{node.lineno}")
    assert found == []


def test_a_missing_corpus_is_corpus_not_found_with_its_name_and_store(tmp_path):
    store = Store(tmp_path)
    store.write("there", synthetic_value(episodes=2, length=5))
    with pytest.raises(CorpusNotFound) as err:
        store.corpus("nope")
    assert (err.value.name, err.value.store, err.value.known) == ("nope", str(tmp_path),
                                                                  ["there"])
    assert str(err.value) == f"no corpus 'nope' in store {tmp_path} (known: there)"


def test_missing_and_stale_models_and_indexes_carry_their_names(tmp_path):
    corpus = Store(tmp_path).write("c", synthetic_value(episodes=4, length=10))
    with pytest.raises(ModelMissing) as err:
        load_model(corpus, "m")
    assert (err.value.corpus, err.value.model, err.value.known) == ("c", "m", [])
    config = BeliefConfig(value="v", threads=1, max_epochs=1)
    train_model(corpus, config, "m")
    model = load_model(corpus, "m")
    with pytest.raises(IndexMissing) as err:
        load_index(corpus, "m")
    assert (err.value.corpus, err.value.model, err.value.index) == ("c", "m", "default")
    build_index(corpus, "m")
    meta_path = corpus.models_dir / "m" / "index" / "default" / "index.json"
    meta = json.loads(meta_path.read_text())  # as if built from another model
    meta_path.write_text(json.dumps(seal({**meta, "model_hash": "another"})))
    with pytest.raises(IndexStale) as err:
        load_index(corpus, "m")
    assert (err.value.corpus, err.value.model, err.value.index) == ("c", "m", "default")
    assert err.value.built_from == {"corpus": corpus.hash, "model": "another"}
    assert err.value.found == {"corpus": corpus.hash, "model": model.hash}


def test_a_bad_setting_names_the_parameter_and_carries_the_value():
    with pytest.raises(BadSetting) as err:
        BeliefConfig(critic_steps=0)
    assert (err.value.param, err.value.value) == ("critic_steps", 0)
    assert str(err.value) == "critic_steps must be >= 1, got 0"


def test_marked_parameters_and_calls_read_as_python():
    err = AocError(f"pass {param('overwrite', True)} or lower {param('lr')} to "
                   f"{param('mode', 'imitation')}; then {call('train', 'c', model='m')}")
    assert str(err) == ("pass overwrite=True or lower lr to mode='imitation'; then "
                        "train('c', model='m')")


def test_typed_errors_survive_pickling_with_their_data():
    # Ray carries a worker's error to the driver by pickling it
    # (bytes this test made from its own objects one line before: no file or user data is unpickled)
    for err in (CorpusNotFound("c", "/s", ["a"]), ModelMissing("c", "m", ["a"], mode="imitation"),
                BadSetting("epsilon", 2.0, f"{param('epsilon')} must be in (0, 1], got 2.0")):
        back = pickle.loads(pickle.dumps(err))
        assert type(back) is type(err) and str(back) == str(err)
        assert back.__dict__ == err.__dict__


def test_a_library_warning_is_an_aoc_warning_that_filters_can_silence(tmp_path, capsys):
    store = Store(tmp_path)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        store.check_writable("x", append=True)
    assert [type(w.message) for w in seen] == [AocWarning]
    assert str(seen[0].message) == (f"append=True: corpus 'x' does not exist in {tmp_path}; "
                                    "creating it")
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.filterwarnings("ignore", category=AocWarning)
        store.check_writable("x", append=True)
    assert capsys.readouterr().err == ""
