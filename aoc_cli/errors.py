"""The one error type of aoc: bad input or usage.

Every command turns an :class:`AocError` into one line on stderr and exit code 2. The message
must say what is wrong and what to do about it.
"""


class AocError(Exception):
    """Bad input or usage; the message is shown to the user as one line.

    ``param``: the library parameter the message starts with (``epsilon must be in (0, 1]``);
    the command line shows the flag instead (:meth:`for_command_line`: ``--epsilon must ...``).
    """

    def __init__(self, message: str, param: str | None = None):
        super().__init__(message)
        self.param = param

    def for_command_line(self) -> str:
        """The message with its parameter's name as a flag (``residual_cap`` ->
        ``--residual-cap``)."""
        text = str(self)
        if self.param and text.startswith(self.param):
            return "--" + self.param.replace("_", "-") + text[len(self.param):]
        return text


def warn(text: str) -> None:
    """A warning the user should see (input accepted, but maybe not as meant): one line on
    stderr, ``aoc: warning: ...``."""
    import sys

    print(f"aoc: warning: {text}", file=sys.stderr)
