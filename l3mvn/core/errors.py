"""One exception type for every user-facing problem.

The CLI prints its message as one line and exits non-zero; the server shows it in the UI. Messages
name the offending file or value and the valid choices.
"""


class L3MVNError(ValueError):
    """A bad input (file, flag, request) explained in one line."""


def one_line(exc: BaseException) -> str:
    """The message on one line: a value quoted into it (a path with a newline) cannot break it."""
    return str(exc).replace("\r", "\\r").replace("\n", "\\n")


def first_line(exc: BaseException) -> str:
    """The first line of a third-party exception's message (or its type), to quote inside ours."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
