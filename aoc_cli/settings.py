"""Settings several stages share, each declared once, and the one convention of the settings
dataclasses (:class:`Settings`, :func:`setting`: validated when built, unknown keys refused,
help and choices on the fields; docs/design.md, "Every setting in one home").

``SMALL_LOG_ROWS``: a log of at most this many rows is *small*. Three choices change there,
each measured on both sides of the bound:

* the training settings (history length, hidden units, weight decay) of a model imitating
  discrete actions are chosen by validation on held-out episodes (:mod:`aoc_cli.training.tuning`;
  never for a value model: a value loss does not track decisions); above it, the paper's;
* an imitation index of discrete actions takes the nearest rows of each action
  (:func:`aoc_cli.index.model_k`; ward at 5k rows: AUC 0.939 -> 0.962; at 100k rows
  no AUC gain and 0.7 points of accuracy lost);
* ``aoc evaluate`` searches the index exactly; above it, an IVF structure built for the run
  (exact search of every held-out step against a large corpus costs ~0.5 ms a step, IVF
  ~0.06 ms with a recall of the k nearest of 0.99999 on ward's beliefs: docs/notes/benchmarks-rounds.md).
"""

from __future__ import annotations

import functools
import re
from dataclasses import MISSING, Field, asdict, field, fields

from aoc_cli.errors import BadSetting, param

#: The largest log (rows) treated as small (module docstring).
SMALL_LOG_ROWS = 20_000


# -- the settings dataclasses' one convention ----------------------------------------------
#
# Every configuration dataclass (BeliefConfig, ControllerConfig, IndexConfig, ...) is frozen,
# derives from :class:`Settings` and declares each field with :func:`setting`: its default,
# its one-line help, and what it may take (``choices``, ``bounds``; ``none``: what None
# means, where None is allowed). Building one checks every field (``__post_init__`` ->
# ``check``), so an invalid config cannot exist: ``dataclasses.replace`` builds (and checks) a
# new one, ``from_dict`` refuses a key that is no setting. A check that involves two fields
# lives in the class's ``check``. The command line reads the help, choices, bounds and defaults
# from the fields (``aoc_cli.cli.fields``), so ``--help`` cannot drift from them.

_ONE_SIDED = re.compile(r"^(>=|>|<=|<) ?(-?[0-9.e+-]+)$")
_INTERVAL = re.compile(r"^([\[(])(-?[0-9.e+-]+), (-?[0-9.e+-]+)([\])])$")


def setting(default=MISSING, *, help: str, choices: tuple | None = None,
            bounds: str | None = None, none: str | None = None, param: str | None = None):
    """A field of a settings dataclass: ``default``; ``help`` (one line, what the setting is:
    the command line shows it); ``choices`` (the values it may take); ``bounds`` (``">= 1"``,
    ``"> 0"``, ``"(0, 1]"``, ``"[0, 1)"``, ...); ``none``: what None means (None is then
    allowed; it is also allowed when the default is None); ``param``: the name of the setting
    in the library's calls and messages when it is not the field's (``OPESettings.gamma`` is
    ``evaluate(ope_gamma=)``)."""
    if bounds is not None and not (_ONE_SIDED.match(bounds) or _INTERVAL.match(bounds)):
        raise ValueError(f"bounds {bounds!r}: write '>= 1', '> 0' or '(0, 1]'")
    metadata = {"help": help}
    for key, value in (("choices", tuple(choices) if choices is not None else None),
                       ("bounds", bounds), ("none", none), ("param", param)):
        if value is not None:
            metadata[key] = value
    return field(default=default, metadata=metadata)


@functools.lru_cache(maxsize=None)
def _edges(bounds: str) -> tuple:
    """``">= 1"`` -> ``(">=", 1.0)``; ``"(0, 1]"`` -> ``("(", 0.0, 1.0, "]")``."""
    one = _ONE_SIDED.match(bounds)
    if one:
        return one.group(1), float(one.group(2))
    left, low, high, right = _INTERVAL.match(bounds).groups()
    return left, float(low), float(high), right


def within(value, bounds: str) -> bool:
    """Whether ``value`` lies within ``bounds`` (:func:`setting`'s form); NaN never does."""
    edges = _edges(bounds)
    if len(edges) == 2:
        op, edge = edges
        return bool(value >= edge if op == ">=" else value > edge if op == ">"
                    else value <= edge if op == "<=" else value < edge)
    left, low, high, right = edges
    above = value >= low if left == "[" else value > low
    below = value <= high if right == "]" else value < high
    return bool(above and below)


def bounds_text(bounds: str) -> str:
    """``"(0, 1]"`` -> ``"in (0, 1]"``; ``">= 1"`` -> ``">= 1"``."""
    return bounds if _ONE_SIDED.match(bounds) else f"in {bounds}"


def param_name(item: Field) -> str:
    """The setting's name in the library's calls and messages."""
    return item.metadata.get("param", item.name)


def none_allowed(item: Field) -> bool:
    """Whether the field may be None (its default is None, or it says what None means)."""
    return item.default is None or "none" in item.metadata


def check_field(item: Field, value) -> None:
    """Raise :class:`~aoc_cli.errors.BadSetting` when ``value`` is not one the field takes."""
    name = param_name(item)
    if value is None:
        if none_allowed(item):
            return
        raise BadSetting(name, value, f"{param(name)} must be given, got None")
    choices = item.metadata.get("choices")
    if choices is not None and value not in choices:
        shown = ", ".join(str(c) for c in choices[:-1]) + f" or {choices[-1]}"
        raise BadSetting(name, value, f"unknown {param(name)} {value!r}: use {shown}")
    bounds = item.metadata.get("bounds")
    if bounds is not None:
        try:
            ok = within(value, bounds)
        except TypeError:
            ok = False
        if not ok:
            raise BadSetting(name, value,
                             f"{param(name)} must be {bounds_text(bounds)}, got {value}")


def given_fields(cls, given, what: str) -> dict:
    """The settings a mapping ``given`` gives a Settings class ``cls``: {field: value} of
    those not None. A key that is no field of ``cls`` is a BadSetting naming it and the
    known ones (``what``: "belief", "controller")."""
    known = {item.name for item in fields(cls)}
    unknown = sorted(set(given) - known)
    if unknown:
        raise BadSetting(unknown[0], given[unknown[0]],
                         f"unknown {what} setting {param(unknown[0])}: the settings are "
                         f"{', '.join(sorted(known))}")
    return {k: v for k, v in given.items() if v is not None}


class Settings:
    """The base of every settings dataclass (the convention above). Subclasses are
    ``@dataclass(frozen=True)``; a check across fields goes in :meth:`check` (call
    ``super().check()`` first)."""

    #: What the settings are of, for messages (``"index"``: "unknown index setting ...").
    label = "a"

    def __post_init__(self) -> None:
        self.check()

    def check(self):
        """Check every field (:func:`check_field`); returns self. Run when built."""
        for item in fields(self):
            check_field(item, getattr(self, item.name))
        return self

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict, strict: bool = True):
        """The settings of ``data`` (checked). ``strict``: a key that is no setting (a typo
        such as ``kidn``) is a :class:`~aoc_cli.errors.BadSetting` naming it and the known
        ones; False (a saved config, which may hold an older aoc's keys) ignores it."""
        known = {item.name for item in fields(cls)}
        unknown = sorted(set(data) - known)
        if strict and unknown:
            key = unknown[0]
            raise BadSetting(key, data[key], f"unknown {cls.label} setting {param(key)}: the "
                             f"settings are {', '.join(sorted(known))}")
        return cls(**{key: value for key, value in data.items() if key in known})
