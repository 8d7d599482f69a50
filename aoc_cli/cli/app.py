"""The typer app. Each command lives in its own module ``aoc_cli.cli.<command>`` exposing
``register(app)``; this module only imports and registers them and turns errors into exit codes:
0 success, 1 a failed run, 2 bad input or usage (one line ``aoc: error: ...`` on stderr, no
traceback unless ``--debug``): a library error (:class:`aoc_cli.errors.AocError`) and a usage
error (an unknown command or option, a missing argument, a value that is not one of the
choices) alike. The line of a library error, with its flags and the command that fixes it,
comes from :mod:`aoc_cli.cli.errors`.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Optional

from aoc_cli.threads import wait_passively

# before anything loads OpenMP (torch, FAISS): its threads wait passively (aoc_cli.threads)
wait_passively()

import typer  # noqa: E402

try:  # typer >= 0.2x carries its own copy of click
    from typer._click import exceptions as usage  # noqa: E402
except ImportError:  # pragma: no cover - older typer on click
    from click import exceptions as usage  # noqa: E402

from aoc_cli import __version__  # noqa: E402
from aoc_cli.cli import (bench, collect, evaluate, explain, export, index, info,  # noqa: E402
                         ingest, rollout, split, train, verify)
from aoc_cli.cli.common import state  # noqa: E402
from aoc_cli.cli.errors import message, showing_warnings  # noqa: E402
from aoc_cli.errors import AocError  # noqa: E402

#: The command modules, in the order of the data flow (``aoc --help`` lists them so).
COMMANDS = [ingest, split, collect, train, index, explain, evaluate, rollout, bench, info,
            verify, export]

app = typer.Typer(
    name="aoc",
    help="Accountable offline control: decisions backed by named rows of a logged dataset.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        print(f"aoc {__version__}")
        raise typer.Exit()


@app.callback()
def _global(
    store: Optional[Path] = typer.Option(
        None, "--store", help="Corpus store folder (default $AOC_STORE, else ./corpora)."
    ),
    debug: bool = typer.Option(False, "--debug", help="Show tracebacks of errors."),
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    state.store = store


for _command in COMMANDS:
    _command.register(app)


def usage_message(err: usage.UsageError) -> str:
    """One line for a usage error, naming the flag: ``unknown --mode: 'x' is not one of ...``."""
    command = err.ctx.command_path if err.ctx is not None else "aoc"
    if isinstance(err, usage.BadParameter) and not isinstance(err, usage.MissingParameter) \
            and err.param is not None:
        hint = err.param_hint or err.param.get_error_hint()
        hint = hint if isinstance(hint, str) else " / ".join(hint)
        text = str(err.message).removeprefix("Value error, ")
        kind = "unknown" if " is not one of " in text else "invalid value for"
        return f"{kind} {hint.replace(chr(39), '')}: {text}"
    message = " ".join(err.format_message().split())
    return f"{message} (see `{command} --help`)"


def global_options_first(args: list[str]) -> list[str]:
    """``aoc``'s own options (``--store DIR``, ``--store=DIR``, ``--debug``) moved before the
    command wherever they were typed, so ``aoc evaluate ward --store s`` works as
    ``aoc --store s evaluate ward`` (no command has options of these names). Nothing after a
    ``--`` is touched.

    Kept on purpose: click parses a group's options only before the command name, and this
    rewrite is what lets ``--store`` (and ``--debug``) follow it without every command
    declaring them. The root itself is resolved in one place,
    :func:`aoc_cli.store.layout.store_root` (``--store``, else ``$AOC_STORE``, else
    ``./corpora``): the callback passes only what was typed."""
    front: list[str] = []
    rest: list[str] = []
    i, end = 0, args.index("--") if "--" in args else len(args)
    while i < end:
        arg = args[i]
        if arg == "--debug" or arg.startswith("--store="):
            front.append(arg)
        elif arg == "--store" and i + 1 < end:
            front += args[i:i + 2]
            i += 1
        else:
            rest.append(arg)
        i += 1
    return front + rest + args[end:]


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point."""
    args = global_options_first(list(argv if argv is not None else sys.argv[1:]))
    debug = "--debug" in args or bool(os.environ.get("AOC_DEBUG"))
    previous = _terminate_like_interrupt()
    code = 0
    try:
        with showing_warnings():  # library warnings: one line ``aoc: warning: ...`` each
            code = app(args=args, prog_name="aoc", standalone_mode=False)
    except Terminated:
        if debug:
            raise
        # every write is a temporary renamed into place: the store holds the previous state
        print("aoc: terminated (the store keeps its previous state)", file=sys.stderr)
        sys.exit(143)
    except usage.NoArgsIsHelpError as err:
        print(err.format_message())
        sys.exit(2)
    except usage.UsageError as err:
        print(f"aoc: error: {usage_message(err)}", file=sys.stderr)
        sys.exit(2)
    except typer.Abort:
        print("aoc: aborted", file=sys.stderr)
        sys.exit(130)
    except AocError as err:
        if debug:
            raise
        print(f"aoc: error: {message(err)}", file=sys.stderr)
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
    if isinstance(code, int) and code != 0:
        sys.exit(code)


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
