"""A griffe extension for the API reference (mkdocs.yml loads it by path).

softplan_jax's docstrings are Google style with two habits that griffe's
Google parser does not read; this rewrites them before parsing, in the
rendered text only (the source is untouched):

* Sphinx roles (``:func:`make_scenario```, ``:class:`~a.b.Gains```) become
  code spans (`` `make_scenario` ``, `` `Gains` ``);
* an ``Args:`` entry that names several parameters over two lines
  (``a, b,`` then ``c: ...``) is joined into one line, so that griffe reads
  one entry ``a, b, c`` instead of failing on the first line;
* a line of prose among the ``Args:`` entries (``Other arguments as plan.``)
  is read as the end of the entry above it.
"""

from __future__ import annotations

import re

import griffe

_ROLE = re.compile(r":(?:func|class|mod|meth|attr|data|obj|exc|const):`~?([^`]+)`")
_CONTINUED_NAMES = re.compile(r"^(\s+[\w*]+(?:, [\w*]+)*),\s*\n\s+(?=[\w*]+(?:, [\w*]+)*:)", re.M)
_ENTRY = re.compile(r"^\s*[\w*]+(?:, [\w*]+)*(?: \([^)]*\))?:(?:\s|$)")
_SECTION = re.compile(r"^\s*(?:Args|Arguments|Parameters|Attributes|Keyword Args|Raises):\s*$")


def _short(match: re.Match) -> str:
    target = match.group(1)
    if match.group(0).split("`")[1].startswith("~"):
        target = target.rsplit(".", 1)[-1]
    return f"`{target}`"


def _prose_into_entries(text: str) -> str:
    out, entry_indent = [], None
    for line in text.split("\n"):
        indent = len(line) - len(line.lstrip())
        if _SECTION.match(line):
            entry_indent = -1
        elif entry_indent is not None and line.strip():
            if entry_indent == -1:
                entry_indent = indent
            elif indent < entry_indent:
                entry_indent = None  # the section ended
            elif indent == entry_indent and not _ENTRY.match(line):
                line = "  " + line
        out.append(line)
    return "\n".join(out)


def clean_docstring(text: str) -> str:
    """The docstring with roles as code spans and the ``Args:`` entries in a form griffe reads."""
    text = _ROLE.sub(_short, text)
    return _prose_into_entries(_CONTINUED_NAMES.sub(r"\1, ", text))


class SoftplanDocstrings(griffe.Extension):
    """Rewrite every docstring with :func:`clean_docstring` when griffe loads it."""

    def on_instance(self, *, node, obj, agent, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = clean_docstring(obj.docstring.value)
