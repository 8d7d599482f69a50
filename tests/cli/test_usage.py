"""The command line as users meet it: usage errors are one line and exit 2, short flags mean
one thing, choices are the library's, the shared options are declared once."""

import pytest

from aoc_cli import __version__


@pytest.mark.parametrize("args, needle", [
    (["bogus"], "No such command 'bogus'"),
    (["info", "--bogus"], "No such option: --bogus"),
    (["rollout"], "Missing argument 'name'"),
    (["rollout", "x"], "Missing option '--env'"),
    (["train", "x", "--mode", "fancy"], "unknown --mode: 'fancy' is not one of 'value', "
                                        "'imitation'"),
    (["rollout", "x", "--env", "maze", "--k", "many"], "invalid value for --k"),
    (["info", "x", "--format", "xml"], "unknown --format / -f: 'xml'"),
])
def test_usage_errors_are_one_line_and_exit_2(aoc_inproc, args, needle):
    code, out, err = aoc_inproc(*args)
    assert code == 2 and out == ""
    assert err.startswith("aoc: error: ") and err.count("\n") == 1, err
    assert needle in err
    assert "╭" not in err and "Traceback" not in err


def test_version_and_completion(aoc_inproc):
    code, out, _ = aoc_inproc("--version")
    assert code == 0 and out.strip() == f"aoc {__version__}"
    code, out, _ = aoc_inproc("--help")
    assert code == 0 and "--install-completion" in out and "--version" in out


def _options(command) -> list:
    return [p for p in command.params if getattr(p, "opts", None)]


def test_a_short_flag_means_one_thing_in_every_command():
    import typer.main

    from aoc_cli.cli.app import app

    group = typer.main.get_command(app)
    meaning: dict = {}
    for name, command in group.commands.items():
        for param in _options(command):
            longs = sorted(o for o in param.opts if o.startswith("--"))
            for short in (o for o in param.opts if not o.startswith("--")):
                meaning.setdefault(short, set()).add(longs[0] if longs else param.name)
    assert meaning["-n"] == {"--episodes"} and meaning["-f"] == {"--format"}
    assert all(len(longs) == 1 for longs in meaning.values()), meaning


def test_the_choices_are_the_librarys():
    from aoc_cli.baselines import BASELINES
    from aoc_cli.belief.config import MODES
    from aoc_cli.cli.common import BeliefMode, IndexKind, OutputFormat, PolicyName, SamplerName
    from aoc_cli.index.search.config import KINDS
    from aoc_cli.cli.output import FORMATS

    assert [p.value for p in PolicyName] == ["aoc", *BASELINES]
    assert tuple(m.value for m in BeliefMode) == MODES
    assert tuple(k.value for k in IndexKind) == KINDS
    assert tuple(f.value for f in OutputFormat) == FORMATS
    assert {s.value for s in SamplerName} == {"uniform", "bc"}


def test_the_index_is_named_alike_in_every_command(aoc_inproc):
    for command in ("index", "rollout", "explain"):
        code, out, _ = aoc_inproc(command, "--help")
        text = " ".join(out.replace("│", " ").split())
        assert code == 0 and "--index,--index-id" in text, command


def test_the_global_options_may_follow_the_command(aoc_inproc, tmp_path):
    """`aoc info x --store DIR --debug` is `aoc --store DIR --debug info x` (users type the
    store after the command; it used to be 'No such option: --store')."""
    from aoc_cli.cli.app import global_options_first

    assert global_options_first(["info", "x", "--store", "s", "--debug"]) == \
        ["--store", "s", "--debug", "info", "x"]
    assert global_options_first(["info", "--store=s", "x", "--", "--debug"]) == \
        ["--store=s", "info", "x", "--", "--debug"]
    assert global_options_first(["info", "x", "--store"]) == ["info", "x", "--store"]
    code, out, err = aoc_inproc("info", "nope", "--store", str(tmp_path / "elsewhere"))
    assert code == 2 and "no corpus 'nope'" in err and "elsewhere" in err, err
