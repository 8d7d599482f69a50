"""How long library work reports progress: one protocol, a plain callable.

    progress(done, total=None, label=None)

``done`` units of ``total`` are finished (``total`` None: unchanged, or not known); ``label``
says what is being done (None: unchanged). Library code calls it and nothing else: it never
imports a terminal library or writes to the terminal. A function that takes ``progress=None``
reports nothing without one. Work in stages reports each stage with its own total and label
to the same callable (a bench: collect, train, index, roll out).

The command line implements it as a bar on stderr (:class:`aoc_cli.cli.output.ProgressBar`);
a test or a program may pass any function of that signature, e.g. ``lambda *a: None``.
"""

from __future__ import annotations

from typing import Iterable, Iterator, Protocol, TypeVar

T = TypeVar("T")


class Progress(Protocol):
    def __call__(self, done: float, total: float | None = None,
                 label: str | None = None) -> None: ...


def tracked(items: Iterable[T], progress: Progress | None, label: str,
            total: int | None = None) -> Iterator[T]:
    """Iterate ``items``, reporting the count done (of ``total``) to ``progress`` after each."""
    if progress is None:
        yield from items
        return
    progress(0, total, label)
    for i, item in enumerate(items, 1):
        yield item
        progress(i, total, label)


def stage(progress: Progress | None, label: str,
          total: float | None = None) -> Progress | None:
    """A Progress for one stage of a longer piece of work: its reports go to ``progress``
    labelled ``label`` (with the stage's own label after a colon). Reports 0 of ``total`` at
    once; None without a ``progress``."""
    if progress is None:
        return None

    def report(done: float, total: float | None = None, sub: str | None = None) -> None:
        progress(done, total, label if sub is None else f"{label}: {sub}")

    report(0, total)
    return report
