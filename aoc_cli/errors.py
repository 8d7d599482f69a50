"""The errors and warnings of aoc: typed errors that carry data, and the :class:`AocWarning`
category.

Every error of bad input or usage is an :class:`AocError` (a command turns it into one line on
stderr and exit code 2). The subclasses carry what went wrong as data (``err.corpus``,
``err.param``, ...), so a library user can act on it without parsing text. Messages name
library *parameters* (``epsilon``), never command-line flags or ``aoc ...`` command lines:
:func:`param` marks a parameter and :func:`call` a library call that fixes the problem; the
library shows them as ``epsilon=0.5`` and ``train('c', model='m')``, the command line
(``aoc_cli.cli.errors``) as ``--epsilon 0.5`` and ``aoc train c --model m``.

Warnings (input accepted, but maybe not as meant) go through :mod:`warnings` with the category
:class:`AocWarning`: filter them with ``warnings.filterwarnings("ignore", category=AocWarning)``;
the command line prints each as one line ``aoc: warning: ...`` on stderr.
"""

from __future__ import annotations

import json
import re
import warnings
from typing import Callable

#: Private-use characters that delimit a marked parameter or call inside a message.
_OPEN, _CLOSE = "\ue000", "\ue001"
_MARK = re.compile(f"{_OPEN}(.*?){_CLOSE}", re.S)
_NO_VALUE = object()


def param(name: str, value=_NO_VALUE) -> str:
    """A parameter named in a message: ``epsilon`` (``--epsilon`` on the command line); with a
    value ``epsilon=0.5`` (``--epsilon 0.5``); ``True`` for a switch (``--overwrite``)."""
    data = {"param": name} if value is _NO_VALUE else {"param": name, "value": value}
    return _OPEN + json.dumps(data, default=str) + _CLOSE


def call(function: str, *args, **kwargs) -> str:
    """A library call named in a message as the fix: ``train('c', model='m')`` (the command
    line shows ``aoc train c --model m``). String values are taken as they are (``"FILE"``,
    ``"..."`` as placeholders)."""
    return _OPEN + json.dumps({"call": function, "args": list(args), "kwargs": kwargs},
                              default=str) + _CLOSE


def render(text: str, show_param: Callable[..., str], show_call: Callable[..., str]) -> str:
    """``text`` with each marked parameter shown by ``show_param(name[, value])`` and each marked
    call by ``show_call(function, args, kwargs)``."""
    def one(match: re.Match) -> str:
        data = json.loads(match.group(1))
        if "call" in data:
            return show_call(data["call"], data["args"], data["kwargs"])
        return show_param(data["param"], *(() if "value" not in data else (data["value"],)))
    return _MARK.sub(one, text)


def _library_param(name: str, *value) -> str:
    return name if not value else f"{name}={value[0]!r}"


def _library_call(function: str, args: list, kwargs: dict) -> str:
    shown = [repr(a) for a in args] + [f"{k}={v!r}" for k, v in kwargs.items()]
    return f"{function}({', '.join(shown)})"


def plain(text: str) -> str:
    """A marked message as a library user reads it."""
    return render(text, _library_param, _library_call)


_param = param  # for the classes whose argument is called param (CorpusExists, ModelExists)


class AocError(Exception):
    """Bad input or usage; the message is shown to the user as one line.

    ``param``: the library parameter the error is about; when the message starts with it
    (``epsilon must be in (0, 1]``) the command line shows the flag instead
    (``--epsilon must ...``). ``marked``: the message with its parameters and calls marked
    (:func:`param`, :func:`call`); ``str(err)`` is it as a library user reads it.
    """

    def __init__(self, message: str, param: str | None = None):
        super().__init__(plain(message))
        self.marked = message
        self.param = param

    def __reduce__(self):  # subclasses take other arguments: rebuild from the state
        return _rebuild, (type(self), self.args, self.__dict__)


def _rebuild(cls, args, state):
    err = cls.__new__(cls)
    err.args = args
    err.__dict__.update(state)
    return err


class RoleOverlap(AocError):
    """Column ``column`` of a table is listed among the observations and also plays the role
    whose parameter is ``role`` (``outcome``, ``reward_column``, ``act_columns``, ...)."""

    def __init__(self, message: str, column: str, role: str):
        super().__init__(message)
        self.column, self.role = column, role


class CorpusNotFound(AocError):
    """No corpus ``name`` in the store at ``store`` (``known``: the corpora it holds)."""

    def __init__(self, name: str, store, known: list[str]):
        super().__init__(f"no corpus {name!r} in store {store} (known: "
                         f"{', '.join(known) or 'none'})")
        self.name, self.store, self.known = name, str(store), list(known)


class CorpusExists(AocError):
    """Corpus ``name`` exists and the write asked neither to replace nor to extend it."""

    def __init__(self, name: str):
        super().__init__(f"corpus {name!r} already exists: pass {_param('overwrite', True)} to "
                         f"replace it or {_param('append', True)} to add to it")
        self.name = name


class Damaged(AocError):
    """A stored file of corpus ``corpus`` is damaged (``what``: which and how)."""

    def __init__(self, corpus: str, what: str):
        super().__init__(f"corpus {corpus!r} is damaged: {what}")
        self.corpus, self.what = corpus, what


class ModelMissing(AocError):
    """Corpus ``corpus`` has no model ``model`` (None: no model at all); ``known``: the models
    it has; ``mode``: the mode the caller needs (``"imitation"``), or None."""

    def __init__(self, corpus: str, model: str | None, known: list[str] = (),
                 mode: str | None = None, why: str = ""):
        if why:
            text = why
        elif model is None:
            text = f"corpus {corpus!r} has no trained model"
        else:
            text = (f"corpus {corpus!r} has no model {model!r} (models: "
                    f"{', '.join(known) or 'none'})")
        super().__init__(text)
        self.corpus, self.model, self.known, self.mode = corpus, model, list(known), mode


class ModelExists(AocError):
    """Model ``model`` of corpus ``corpus`` exists and the training did not ask to replace
    it."""

    def __init__(self, corpus: str, model: str):
        super().__init__(f"model {model!r} of corpus {corpus!r} already exists: pass "
                         f"{_param('overwrite', True)} to replace it, or choose another "
                         f"{_param('model')}")
        self.corpus, self.model = corpus, model


class ModelStale(AocError):
    """Model ``model`` was trained on another version of corpus ``corpus``
    (``built_from``: the corpus hash it was trained on, ``found``: the hash now)."""

    def __init__(self, corpus: str, model: str, built_from: str, found: str):
        super().__init__(f"model {model!r} was trained on a different version of corpus "
                         f"{corpus!r} (hash {built_from[:12]}, now {found[:12]})")
        self.corpus, self.model, self.built_from, self.found = corpus, model, built_from, found


class IndexMissing(AocError):
    """No index ``index`` of model ``model`` of corpus ``corpus``."""

    def __init__(self, corpus: str, model: str, index: str):
        super().__init__(f"no index {index!r} for model {model!r} of corpus {corpus!r}")
        self.corpus, self.model, self.index = corpus, model, index


class IndexStale(AocError):
    """Index ``index`` (of model ``model`` of corpus ``corpus``) was built from other data than
    it is used with: ``built_from`` what it records, ``found`` what it met (both dicts of
    hashes, e.g. ``{"corpus": ..., "model": ...}``)."""

    def __init__(self, corpus: str, model: str, index: str, built_from: dict, found: dict):
        super().__init__(f"index {index!r} was built from another version of corpus "
                         f"{corpus!r} or model {model!r}")
        self.corpus, self.model, self.index = corpus, model, index
        self.built_from, self.found = dict(built_from), dict(found)


class NoRewards(AocError):
    """Corpus ``corpus`` has no rewards, and ``needs`` (what asked for them) cannot work
    without; ``why``: the whole message (marked)."""

    def __init__(self, corpus: str, needs: str, why: str, param: str | None = None):
        super().__init__(why, param)
        self.corpus, self.needs = corpus, needs


class BadSetting(AocError):
    """Setting ``param`` has a value it cannot take: ``value``; ``why``: the message, with the
    setting marked (``f"{param('epsilon')} must be in (0, 1], got {epsilon}"``)."""

    def __init__(self, param: str, value, why: str):
        super().__init__(why, param)
        self.value, self.why = value, why


class BadInput(AocError):
    """Input file ``path`` cannot be used: ``why`` (the message, marked); ``where``: where in it
    (a row, a column, a key) or None; ``param``: the parameter that named the file, if any."""

    def __init__(self, path, why: str, where: str | None = None, param: str | None = None):
        super().__init__(why, param)
        self.path, self.where, self.why = (None if path is None else str(path)), where, why


class Locked(AocError):
    """``what`` is being written by another process (``pids``: its process ids, if known)."""

    def __init__(self, what: str, pids: list[int] = ()):
        who = ("pid " + ", ".join(str(p) for p in pids)) if pids else "another process"
        super().__init__(f"{what} is being written by {who}: wait until it has finished, then "
                         "run this again")
        self.what, self.pids = what, list(pids)


class AocWarning(UserWarning):
    """A warning of aoc: input accepted, but maybe not as meant. ``str()`` is the message as a
    library user reads it; ``marked`` keeps its parameters for the command line."""

    def __init__(self, message: str):
        super().__init__(plain(message))
        self.marked = message


def warn(text: str, stacklevel: int = 2) -> None:
    """Warn the user (``text`` may mark parameters, :func:`param`): an :class:`AocWarning`
    through :func:`warnings.warn`."""
    warnings.warn(AocWarning(text), stacklevel=stacklevel + 1)
