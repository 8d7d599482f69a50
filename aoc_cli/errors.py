"""The one error type of aoc: bad input or usage.

Every command turns an :class:`AocError` into one line on stderr and exit code 2. The message
must say what is wrong and what to do about it.
"""


class AocError(Exception):
    """Bad input or usage; the message is shown to the user as one line."""


def warn(text: str) -> None:
    """A warning the user should see (input accepted, but maybe not as meant): one line on
    stderr, ``aoc: warning: ...``."""
    import sys

    print(f"aoc: warning: {text}", file=sys.stderr)
