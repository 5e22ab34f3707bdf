"""MkDocs hook: the docstrings' Sphinx roles (``:class:`~gaussim.world.Material` ``) shown as code.

mkdocstrings renders a docstring as Markdown, where a role's backticks make a code span and leave
the role's name in front of it; this drops the name, and a leading ``~`` with the path it shortens.
"""

import re

ROLE = re.compile(r":(?:class|func|meth|attr|mod|data|exc|obj):<code>(~?)([^<]*)</code>")


def _code(match: re.Match) -> str:
    target = match[2].rsplit(".", 1)[-1] if match[1] else match[2]
    return f"<code>{target}</code>"


def on_page_content(html: str, **kwargs: object) -> str:
    return ROLE.sub(_code, html)
