"""One exception type for every user-facing problem.

The CLI prints its message as one line and exits non-zero; the server shows it in the UI. Messages
name the offending file or value and the valid choices.
"""

import reprlib


class L3MVNError(ValueError):
    """A bad input (file, flag, request) explained in one line."""


def one_line(exc: BaseException) -> str:
    """The message on one line: a value quoted into it (a path with a newline) cannot break it."""
    return str(exc).replace("\r", "\\r").replace("\n", "\\n")


def first_line(exc: BaseException | str) -> str:
    """The first line of a third-party exception's message (or its type), or of a text read from a
    file (an error row's), to quote inside ours."""
    text = str(exc).strip()
    if text:
        return text.splitlines()[0]
    return type(exc).__name__ if isinstance(exc, BaseException) else "no message"


def show_value(value: object) -> str:
    """A bad value quoted in an error message: short and on one line (a whole list could be huge, and
    numpy's reprs span several lines)."""
    shape, dtype = getattr(value, "shape", None), getattr(value, "dtype", None)
    if shape is not None and dtype is not None:
        return f"an array of shape {shape} and dtype {dtype}"
    return reprlib.repr(value).replace("\n", " ")
