"""Text from files, configs and clients made safe for the page: every view puts such text through here.

viser renders a markdown element's raw HTML unsanitised (script included) and an HTML element as
``innerHTML``, so a result key, an error message, a recording's name or a decision line read from a
colleague's file would otherwise become elements in the dashboard's own origin. ``md`` turns text
into markdown that shows those characters and nothing else (no element, no link, no emphasis, no
table cell break, no new block); ``html`` does the same for an HTML element's text or attribute;
``code`` is ``md`` in a monospaced span. Markup the views write themselves stays as it is: only the
values interpolated into it go through these.
"""

from __future__ import annotations

import html as _html
import re

# The marks that CommonMark or GFM give a meaning to anywhere in a line (emphasis, code, links and
# images, table cells, strikethrough, escapes), escaped with a backslash; '&', '<' and '>' become
# entities instead (a backslash before an entity would show the entity). Marks that only mean
# something at the start of a line (headings, lists, quotes) are escaped there.
_INLINE_MARKS = re.compile(r"([\\`*_\[\]!|~])")
_HEADING_OR_BULLET = re.compile(r"^(\s*)([#+\-=])")
_NUMBERED = re.compile(r"^(\s*\d+)([.)])")
_LINE_BREAKS = re.compile(r"[\r\n\u2028\u2029\x0b\x0c\x85]+")
_CONTROL = re.compile(r"[\x00-\x08\x0e-\x1f\x7f]")


def _one_line(value: object) -> str:
    """``value`` as one line of text: line breaks become spaces (a break could start a new block or
    close a table row) and control characters are dropped."""
    return _CONTROL.sub("", _LINE_BREAKS.sub(" ", str(value)))


def md(value: object) -> str:
    """``value`` as markdown text that renders exactly as its characters, on one line."""
    escaped = _INLINE_MARKS.sub(r"\\\1", _one_line(value))
    escaped = _NUMBERED.sub(r"\1\\\2", _HEADING_OR_BULLET.sub(r"\1\\\2", escaped))
    return _html.escape(escaped, quote=False)


def code(value: object) -> str:
    """``value`` in a monospaced span inside markdown (a backtick span could be closed by the value)."""
    return f"<code>{md(value)}</code>"


def html(value: object) -> str:
    """``value`` as text inside an HTML element or a quoted attribute."""
    return _html.escape(_one_line(value), quote=True)
