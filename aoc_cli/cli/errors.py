"""The library's errors and warnings as the command line shows them: one line each, with flags
for parameters and the ``aoc ...`` command that fixes the problem.

The library (:mod:`aoc_cli.errors`) names parameters (``epsilon``) and library calls
(``train('c')``); this module alone knows the flags and commands: :func:`message` turns an
:class:`~aoc_cli.errors.AocError` into the text after ``aoc: error:``, :func:`showing_warnings`
prints each :class:`~aoc_cli.errors.AocWarning` as ``aoc: warning: ...`` on stderr.
"""

from __future__ import annotations

import contextlib
import sys
import warnings
from typing import Iterator

from aoc_cli.errors import (AocError, AocWarning, CorpusNotFound, Damaged, IndexMissing,
                            IndexStale, ModelMissing, ModelStale, render)
from aoc_cli.store import DEFAULT_INDEX

#: Library parameters whose flag is not ``--`` + the name with dashes.
FLAGS = {"max_epochs": "--epochs", "episode_rates": "--episode-rate", "fmt": "--from",
         "tag_columns": "--tag-column", "tags": "--tag", "columns_file": "--columns",
         "queries": "--input", "steps_file": "--steps"}

#: Library calls whose command is not their name.
COMMANDS = {"build_index": "index"}


def flag(name: str, *value) -> str:
    """``residual_cap`` -> ``--residual-cap``; with a value ``--residual-cap 0.5``; ``True``
    (a switch) the flag alone."""
    text = FLAGS.get(name, "--" + name.replace("_", "-"))
    if not value or value[0] is True:
        return text
    return f"{text} {value[0]}"


def command(function: str, args: list, kwargs: dict) -> str:
    """The command line of a library call: ``train('c', model='m')`` -> ``aoc train c
    --model m``."""
    words = ["aoc", COMMANDS.get(function, function.replace("_", "-"))]
    words += [str(a) for a in args] + [flag(k, v) for k, v in kwargs.items()]
    return " ".join(words)


def text(marked: str) -> str:
    """A marked library message (:func:`aoc_cli.errors.param`, :func:`~aoc_cli.errors.call`)
    with flags and commands."""
    return render(marked, flag, command)


def _train(corpus: str, model: str | None, *extra: str) -> str:
    words = ["aoc train", corpus] + ([f"--model {model}"] if model is not None else [])
    return " ".join(words + list(extra))


def _index(corpus: str, model: str, index: str) -> str:
    line = f"aoc index {corpus} --model {model}"
    if index != DEFAULT_INDEX:
        line += f" --index-id {index} (with its --episode-rate)"
    return line


def hint(err: AocError) -> str:
    """What to run, for the typed errors that have a command as their fix ('' for the
    others), with the separator it follows the message with."""
    if isinstance(err, CorpusNotFound):
        return "; create it with `aoc ingest` or `aoc collect`"
    if isinstance(err, Damaged):
        return (f"; run `aoc verify {err.corpus}` to see every damaged file, then re-ingest or "
                "re-collect it with --overwrite")
    if isinstance(err, ModelMissing):
        extra = ("--mode", err.mode) if err.mode else ()
        return f": run `{_train(err.corpus, err.model, *extra)}`"
    if isinstance(err, ModelStale):
        return f": re-run `aoc train {err.corpus} --model {err.model} --overwrite`"
    if isinstance(err, IndexMissing):
        return f": run `{_index(err.corpus, err.model, err.index)}`"
    if isinstance(err, IndexStale):
        return f": rebuild it with `{_index(err.corpus, err.model, err.index)}`"
    return ""


def message(err: AocError) -> str:
    """The one line a user sees after ``aoc: error:`` for ``err``."""
    marked = getattr(err, "marked", None) or str(err)  # (Ray's copy reaches it via its cause)
    param = getattr(err, "param", None)
    line = text(marked)
    if param and marked.startswith(param):  # the plain ``param=`` hook
        line = flag(param) + line[len(param):]
    return line + hint(err)


def warning_line(message) -> str:
    """The line of a library warning: ``aoc: warning: ...`` with flags for its parameters."""
    text = message.marked if isinstance(message, AocWarning) else str(message)
    return f"aoc: warning: {render(text, flag, command)}"


@contextlib.contextmanager
def showing_warnings() -> Iterator[None]:
    """Within: every :class:`AocWarning` is shown (each time, not once per place) as one line
    on stderr (:func:`warning_line`); every other warning goes where it went before (Python's
    display, or a test runner's record). Filters and display come back after."""
    other = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, AocWarning):
            print(warning_line(message), file=sys.stderr)
        else:
            other(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        warnings.simplefilter("always", AocWarning)
        warnings.showwarning = show
        yield
