r"""A Griffe extension that lets mkdocstrings render our reStructuredText-flavoured docstrings.

The docstrings use Sphinx roles (``:class:`~risk_env.Scenario```), doctest examples (``>>>``)
and markdown tables whose cells may hold a ``|`` (``R_{k+1|k}``). This extension rewrites them
when the packages are loaded, before mkdocstrings renders anything:

- a role becomes an optional cross-reference: a link when the target is on the site, plain code
  otherwise (private names, other libraries);
- a doctest block becomes a ``pycon`` code block;
- a ``|`` inside braces in a table row is escaped, and inside maths (``$R_{k+1|k}$``) written
  ``\vert``;
- an ``Args:`` entry that documents several parameters at once (``tol, max_iter: ...``) becomes
  one entry per parameter, so the parameters table lists each.

Configured in ``mkdocs.yml`` (``extensions: [docs/griffe_rst.py]``); nothing here runs at import
of the project's packages.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:mod|class|func|meth|data|attr|obj|exc):`(~?)([^`]+)`")
_EXPLICIT = re.compile(r"(.+?) <([\w.]+)>")
_BRACED_PIPE = re.compile(r"\{([^{}|]*)\|([^{}]*)\}")
_INLINE_MATHS = re.compile(r"(?<![\\$])\$[^$\n]+?\$")
_PACKAGES = ("risk_env", "agents", "benchmarks")


def _identifier(obj: griffe.Object, target: str) -> str | None:
    """The full path of ``target`` as written in ``obj``'s docstring, or None when unknown."""
    if target.startswith(_PACKAGES):
        return target
    head, _, rest = target.partition(".")
    scope: griffe.Object | None = obj
    while scope is not None:
        try:
            resolved = scope.resolve(head)
        except (griffe.NameResolutionError, AttributeError, KeyError):
            scope = scope.parent
            continue
        return f"{resolved}.{rest}" if rest else resolved
    return None


def roles(obj: griffe.Object, text: str) -> str:
    """Sphinx roles in ``text`` as optional autorefs cross-references."""

    def replace(match: re.Match[str]) -> str:
        short, target = match.group(1) == "~", " ".join(match.group(2).split())
        title = target.rsplit(".", 1)[-1] if short else target
        if (explicit := _EXPLICIT.fullmatch(target)) is not None:  # Sphinx's ``title <target>``
            title, target = explicit.groups()
        identifier = _identifier(obj, target)
        if identifier is None or any(part.startswith("_") for part in identifier.split(".")):
            return f"`{title}`"
        return f'<autoref identifier="{identifier}" optional><code>{title}</code></autoref>'

    return _ROLE.sub(replace, text)


def doctests(text: str) -> str:
    """Doctest blocks (``>>>`` lines and their output, up to a blank line) as fenced code."""
    out: list[str] = []
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith(">>>"):
            indent = line[: len(line) - len(line.lstrip())]
            block = []
            while i < len(lines) and lines[i].strip():
                block.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i])
                i += 1
            out += [f"{indent}```pycon", *(indent + b for b in block), f"{indent}```"]
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


def maths_pipes(line: str) -> str:
    r"""``|`` inside the inline maths of a markdown table row as ``\vert``, which cannot end a cell
    (an escaped ``\|`` would reach MathJax as the norm bars)."""
    return _INLINE_MATHS.sub(lambda m: m.group(0).replace("|", r"\vert "), line)


def table_pipes(text: str) -> str:
    r"""Escape ``|`` inside braces in markdown table rows (``R_{k+1|k}``); in maths, ``\vert``."""
    lines = []
    for line in text.split("\n"):
        if line.lstrip().startswith("|"):
            line = _BRACED_PIPE.sub(r"{\1\\|\2}", maths_pipes(line))
        lines.append(line)
    return "\n".join(lines)


_ARGS = re.compile(r"^(\s*)(Args|Arguments|Parameters):\s*$")
_SHARED = re.compile(r"^(\s+)(\*{0,2}\w+(?:, \*{0,2}\w+)+): (.*)$")


def shared_args(text: str) -> str:
    """``a, b: description`` entries of an ``Args:`` section as one entry per parameter."""
    lines = text.split("\n")
    out: list[str] = []
    section_indent: int | None = None
    i = 0
    while i < len(lines):
        line = lines[i]
        if (m := _ARGS.match(line)) is not None:
            section_indent = len(m.group(1))
            out.append(line)
            i += 1
            continue
        indent = len(line) - len(line.lstrip())
        if section_indent is not None and line.strip() and indent <= section_indent:
            section_indent = None
        shared = _SHARED.match(line) if section_indent is not None else None
        if shared is None:
            out.append(line)
            i += 1
            continue
        lead, names, first = shared.groups()
        body = [first]
        i += 1
        while i < len(lines) and lines[i].strip() and len(lines[i]) - len(lines[i].lstrip()) > len(lead):
            body.append(lines[i])
            i += 1
        for name in names.split(", "):
            out.append(f"{lead}{name}: {body[0]}")
            out += body[1:]
    return "\n".join(out)


class RstDocstrings(griffe.Extension):
    """Rewrites every docstring of a loaded package (see the module docstring)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        self._walk(pkg, set())

    def _walk(self, obj: griffe.Object, seen: set[str]) -> None:
        if obj.path in seen:
            return
        seen.add(obj.path)
        if obj.docstring is not None:
            text = obj.docstring.value
            obj.docstring.value = shared_args(table_pipes(doctests(roles(obj, text))))
        for member in obj.members.values():
            if not member.is_alias:
                self._walk(member, seen)
