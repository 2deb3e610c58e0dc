"""What every benchmark command shares on its command line: usage, plain help, shown defaults.

Each ``python -m benchmarks.NAME`` builds its parser with :func:`parser`, so ``--help`` reads the
same everywhere: the usage line names the command as it is typed, the description is the first
paragraph of the module docstring without reStructuredText markup, every flag shows its default,
and the example commands of the docstring follow as an epilog.
"""

from __future__ import annotations

import argparse
import re
import textwrap

_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")
_LITERAL = re.compile(r"``([^`]+)``")
_STRONG = re.compile(r"\*\*([^*]+)\*\*")


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Defaults after every flag's help; description and epilog kept as written.

    A flag whose default is ``None`` says in its own help what ``None`` means, with
    ``(default: ...)``, so no ``(default: None)`` appears.
    """

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "(default" in text or action.default is None:
            return text
        return super()._get_help_string(action)


def plain(text: str) -> str:
    """``text`` without reStructuredText markup (roles, double back quotes, bold), wrapped to 90."""
    text = _ROLE.sub(lambda m: m.group(1), text)
    text = _LITERAL.sub(r"\1", text)
    text = _STRONG.sub(r"\1", text)
    return textwrap.fill(" ".join(text.split()), width=90, break_on_hyphens=False)


def comma_list(text: str) -> list[str]:
    """The items of a comma-separated option value, stripped, empty ones dropped."""
    return [item.strip() for item in text.split(",") if item.strip()]


def examples(doc: str) -> list[str]:
    """The example commands (lines starting ``python -m benchmarks.``) of a module docstring."""
    lines = [line.strip() for line in doc.splitlines()]
    return [line for line in lines if line.startswith("python -m benchmarks.")]


def parser(name: str, doc: str | None) -> argparse.ArgumentParser:
    """The parser of ``python -m benchmarks.NAME``, described by its module docstring ``doc``."""
    doc = doc or ""
    first = doc.strip().split("\n\n")[0]
    commands = examples(doc)
    epilog = "examples:\n" + "\n".join(f"  {c}" for c in commands) if commands else None
    return argparse.ArgumentParser(
        prog=f"python -m benchmarks.{name}",
        description=plain(first),
        epilog=epilog,
        formatter_class=HelpFormatter,
    )


def add_sweep_options(parser: argparse.ArgumentParser) -> None:
    """``--workers`` and ``--ray``: where the shared sweep (:mod:`benchmarks.sweep`) runs the jobs."""
    parser.add_argument("--workers", type=int, default=None, help="processes (default: one per core)")
    parser.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=False,
        metavar="ADDRESS",
        help="run on Ray: a local instance without ADDRESS, else the cluster at ADDRESS"
        " (default: a process pool)",
    )
