"""The typer app. Each command lives in its own module ``aoc_cli.cli.<command>`` exposing
``register(app)``; this module only wires them up and turns errors into exit codes:
0 success, 1 a failed run, 2 bad input or usage (one line on stderr, no traceback unless
``--debug``).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from pathlib import Path
from typing import Optional

import typer

from aoc_cli.cli.common import state
from aoc_cli.errors import AocError

#: Command modules in the order of the data flow.
COMMANDS = ["ingest", "collect", "train", "index", "explain", "evaluate", "rollout", "bench",
            "info", "verify"]

app = typer.Typer(
    name="aoc",
    help="Accountable offline control: decisions backed by named rows of a logged dataset.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


@app.callback()
def _global(
    store: Optional[Path] = typer.Option(
        None, "--store", envvar="AOC_STORE", help="Corpus store folder (default ./corpora)."
    ),
    debug: bool = typer.Option(False, "--debug", help="Show tracebacks of errors."),
) -> None:
    state.store = store
    state.debug = debug


for _name in COMMANDS:
    if importlib.util.find_spec(f"aoc_cli.cli.{_name}") is not None:
        importlib.import_module(f"aoc_cli.cli.{_name}").register(app)


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point. Click handles usage errors itself (exit 2)."""
    debug = "--debug" in (argv if argv is not None else sys.argv[1:]) or bool(
        os.environ.get("AOC_DEBUG"))
    previous = _terminate_like_interrupt()
    try:
        app(args=argv, prog_name="aoc")
    except Terminated:
        if debug:
            raise
        # every write is a temporary renamed into place: the store holds the previous state
        print("aoc: terminated (the store keeps its previous state)", file=sys.stderr)
        sys.exit(143)
    except AocError as err:
        if debug:
            raise
        print(f"aoc: error: {err}", file=sys.stderr)
        sys.exit(2)
    except Exception as err:
        if debug:
            raise
        print(
            f"aoc: internal error: {type(err).__name__}: {err} (run with --debug for the traceback)",
            file=sys.stderr,
        )
        sys.exit(1)
    finally:
        if previous is not None:
            import signal

            signal.signal(signal.SIGTERM, previous)


class Terminated(BaseException):
    """Raised by SIGTERM: unwinds like KeyboardInterrupt (Ctrl-C), past every ``except
    Exception``, so the temporaries of a write in progress are removed."""


def _terminate_like_interrupt():
    """SIGTERM raises :class:`Terminated`, as Ctrl-C raises KeyboardInterrupt, so the store
    keeps its previous state; exit code 143 (128 + SIGTERM). Returns the previous handler
    (restored when :func:`main` returns)."""
    import signal
    import threading

    def handler(signum, frame):
        raise Terminated

    if threading.current_thread() is threading.main_thread():
        return signal.signal(signal.SIGTERM, handler)
    return None
