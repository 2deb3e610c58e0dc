"""What every benchmark command shares on its command line: usage, plain help, shown defaults,
checked values, comma lists, and where the results go.

Each ``python -m benchmarks.NAME`` builds its parser with :func:`parser`, so ``--help`` reads the
same everywhere: the usage line names the command as it is typed, the description is the first
paragraph of the module docstring without reStructuredText markup, every flag shows its default,
and the example commands of the docstring follow as an epilog. Flags are never abbreviated. Every
value is checked while the command line is read (the ``type=`` functions below: a bad value is an
error naming its flag), and :func:`open_output` checks ``--out`` before any work.
"""

from __future__ import annotations

import argparse
import math
import re
import textwrap
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from benchmarks import agent_names
from benchmarks.output import OutputError, OutputSet

_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")
_LITERAL = re.compile(r"``([^`]+)``")
_STRONG = re.compile(r"\*\*([^*]+)\*\*")
_MATHS = re.compile(r"\$\$?([^$]+)\$\$?")
_TEX_SYMBOLS = {
    "le": "<=",
    "ge": ">=",
    "pm": "+-",
    "to": "->",
    "cdot": "*",
    "times": "x",
    "dots": "...",
    "in": "in",
}
_TEX_COMMAND = re.compile(r"\\([A-Za-z]+|[,;!| {}_])")
_TEX_TEXT = re.compile(r"\\(?:mathrm|text|mathbf|operatorname)\{([^{}]*)\}")
_TEX_FRACTION = re.compile(r"\\frac\{([^{}]*)\}\{([^{}]*)\}")
_TEX_ROOT = re.compile(r"\\sqrt\{([^{}]*)\}")
_TEX_GROUP = re.compile(r"(?<![_^\\])\{([^{}]*)(?<!\\)\}")


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


def plain_maths(tex: str) -> str:
    r"""A formula of the docs (the TeX between ``$`` signs) as a terminal shows it: commands become
    their names or symbols (``\epsilon`` becomes epsilon, ``\le`` becomes <=), fractions and roots
    are written out, braces go except around a subscript or power of several characters."""

    def command(match: re.Match[str]) -> str:
        name = match.group(1)
        if name in "|{}_":
            return "||" if name == "|" else name
        return _TEX_SYMBOLS.get(name, name) if name.isalpha() else " "

    def part(text: str) -> str:
        return text if re.fullmatch(r"[\w\\]+", text) else f"({text})"

    tex = _TEX_FRACTION.sub(lambda m: f"{part(m.group(1))}/{part(m.group(2))}", _TEX_TEXT.sub(r"\1", tex))
    tex = _TEX_ROOT.sub(r"sqrt(\1)", tex)
    while _TEX_GROUP.search(tex):
        tex = _TEX_GROUP.sub(r"\1", tex)
    tex = re.sub(r"([_^])\{(\w)\}", r"\1\2", tex)  # x_{k} -> x_k; x_{k+1} stays
    return _TEX_COMMAND.sub(command, tex)


def plain(text: str) -> str:
    """``text`` without reStructuredText markup (roles, double back quotes, bold) and with its maths
    as plain text (:func:`plain_maths`), wrapped to 90."""
    text = _MATHS.sub(lambda m: plain_maths(m.group(1)), text)
    text = _ROLE.sub(lambda m: m.group(1), text)
    text = _LITERAL.sub(r"\1", text)
    text = _STRONG.sub(r"\1", text)
    return textwrap.fill(" ".join(text.split()), width=90, break_on_hyphens=False)


def comma_list(text: str) -> list[str]:
    """The items of a comma-separated option value, stripped. Raises ``ValueError`` for an empty
    list or an empty item (``"a,,b"``)."""
    items = [item.strip() for item in str(text).split(",")]
    if not any(items):
        raise ValueError(f"expected a comma list, got {text!r}")
    if "" in items:
        raise ValueError(f"empty item in the comma list {text!r}")
    return items


def examples(doc: str) -> list[str]:
    """The example commands (lines starting ``python -m benchmarks.``, with the lines a trailing
    backslash continues) of a module docstring, each on one line."""
    out: list[str] = []
    going = False
    for raw in doc.splitlines():
        line = raw.strip()
        if going:
            out[-1] += " " + line.rstrip("\\").strip()
        elif line.startswith("python -m benchmarks."):
            out.append(line.rstrip("\\").strip())
        else:
            continue
        going = line.endswith("\\")
    return [_tidy(c) for c in out]


def _tidy(command: str) -> str:
    """``command`` with single spaces, a trailing ``# comment`` two spaces after it."""
    code, hash_, comment = command.partition(" #")
    return " ".join(code.split()) + (f"  # {comment.strip()}" if hash_ else "")


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def positive_int(text: str) -> int:
    """``type=`` of a count >= 1."""
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def nonnegative_int(text: str) -> int:
    """``type=`` of a count or seed >= 0."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """``type=`` of a finite number > 0."""
    value = _number(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def nonnegative_float(text: str) -> float:
    """``type=`` of a finite number >= 0."""
    value = _number(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """``type=`` of a finite number."""
    value = _number(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def unit_interval(text: str) -> float:
    """``type=`` of a number in [0, 1)."""
    value = _number(text)
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1), got {text!r}")
    return value


def unit_interval_closed(text: str) -> float:
    """``type=`` of a number in [0, 1]."""
    value = _number(text)
    if not 0 <= value <= 1:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}")
    return value


def fraction(text: str) -> float:
    """``type=`` of a share in (0, 1]."""
    value = _number(text)
    if not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"expected a share in (0, 1], got {text!r}")
    return value


def discount(text: str) -> float:
    """``type=`` of a discount factor in (0, 1]."""
    value = _number(text)
    if not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"expected a discount factor in (0, 1], got {text!r}")
    return value


def positive_or_inf(text: str) -> float:
    """``type=`` of a length or size > 0, ``inf`` for none."""
    value = _number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0 or inf, got {text!r}")
    return value


def time_cap(text: str) -> float:
    """``type=`` of a wall-time cap [s]: > 0, ``inf`` for none."""
    value = _number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a time > 0 [s] or inf, got {text!r}")
    return value


def choices_list(choices: Iterable[str], what: str = "value") -> Callable[[str], list[str]]:
    """``type=`` of a comma list of ``choices`` (each a ``what``)."""
    valid = tuple(choices)

    def convert(text: str) -> list[str]:
        items = _items(text)
        bad = [item for item in items if item not in valid]
        if bad:
            names = ", ".join(repr(b) for b in bad)
            raise argparse.ArgumentTypeError(f"unknown {what} {names}; expected from {', '.join(valid)}")
        return items

    return convert


def numbers_list(convert: Callable[[str], Any]) -> Callable[[str], list[Any]]:
    """``type=`` of a comma list of values, each read by ``convert`` (a ``type=`` function)."""

    def read(text: str) -> list[Any]:
        return [convert(item) for item in _items(text)]

    return read


def agents_list(
    kinds: tuple[str, ...] = agent_names.KINDS, tolerance: bool = True, budget: bool = True
) -> Callable[[str], list[agent_names.AgentName]]:
    """``type=`` of a comma list of agents (:mod:`benchmarks.agent_names`)."""

    def read(text: str) -> list[agent_names.AgentName]:
        try:
            return agent_names.parse_agents(text, kinds, tolerance, budget)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None

    return read


def _items(text: str) -> list[str]:
    try:
        return comma_list(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_output_options(
    parser: argparse.ArgumentParser, default: Path | None, help: str, resume: bool = False
) -> None:
    """``--out`` (a folder; ``default`` None: print only), ``--overwrite`` and, for sweeps,
    ``--resume`` (:mod:`benchmarks.output`)."""
    parser.add_argument("--out", type=Path, default=default, help=help)
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace results of another configuration in --out (and discard an interrupted run's chunks)",
    )
    if resume:
        parser.add_argument(
            "--resume",
            action="store_true",
            help="go on from the finished chunks of an interrupted run of the same configuration",
        )


def open_output(
    parser: argparse.ArgumentParser,
    args: argparse.Namespace | Any,
    name: str,
    files: Iterable[str],
    argv: list[str] | None,
    out: Path | None = None,
    exclude: Iterable[str] = (),
) -> OutputSet:
    """The output set of this run (:class:`benchmarks.output.OutputSet`), checked before any
    work: a problem is a usage error naming its flag."""
    options = vars(args) if isinstance(args, argparse.Namespace) else dict(args.__dict__)
    command = parser.prog.removeprefix("python -m benchmarks.")
    output = OutputSet(
        command,
        options["out"] if out is None else out,
        name,
        files,
        options,
        argv,
        exclude,
        overwrite=bool(options.get("overwrite")),
        resume=bool(options.get("resume")),
    )
    try:
        output.check()
    except OutputError as error:
        parser.error(str(error))
    return output


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
        allow_abbrev=False,
    )


def add_sweep_options(parser: argparse.ArgumentParser) -> None:
    """``--workers`` and ``--ray``: where the shared sweep (:mod:`benchmarks.sweep`) runs the jobs."""
    parser.add_argument(
        "--workers", type=positive_int, default=None, help="processes (default: one per core)"
    )
    parser.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=False,
        metavar="ADDRESS",
        help="run on Ray: a local instance without ADDRESS, else the cluster at ADDRESS"
        " (default: a process pool)",
    )


class Renamed(argparse.Action):
    """A flag of an earlier version: still read (into the new flag's ``dest``), with a deprecation
    message naming the new spelling. Hidden from ``--help``; removed in the next release."""

    def __init__(self, option_strings: list[str], dest: str, new: str = "", **kwargs: Any) -> None:
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, **kwargs)
        self.new = new

    def __call__(self, parser: Any, namespace: Any, values: Any, option_string: str | None = None) -> None:
        import sys

        print(f"{parser.prog}: {option_string} is deprecated, use {self.new}", file=sys.stderr)
        setattr(namespace, self.dest, values)


class CommaList(argparse.Action):
    """A comma-list flag (``type=`` reads the list) that tells the space-separated spelling of
    earlier versions (``--num-envs 1 64``) what it is now (``--num-envs 1,64``)."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: Any) -> None:
        kwargs.setdefault("nargs", "+")
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser: Any, namespace: Any, values: Any, option_string: str | None = None) -> None:
        if len(values) > 1:
            joined = ",".join(str(x) for value in values for x in value)
            parser.error(f"argument {option_string}: takes a comma list now: {option_string} {joined}")
        setattr(namespace, self.dest, values[0])
