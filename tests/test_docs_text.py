"""What the docs site says: maths typeset as maths, not shown as code, and the software as it is,
not the project's history (that lives in CHANGELOG.md).

The checks read the sources the site is built from, which is cheap: every page under ``docs/``
(and the results files a page includes), and, for the API pages, the docstrings and ``--help``
texts of the modules they render. ``test_the_built_site_*`` (``slow``) builds the site and checks
its HTML. The scope is the constants below; the tool that lists what they find is
:func:`findings` (``python tests/test_docs_text.py [--all] [PATH ...]``).
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from html import unescape
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
SOURCES = ("risk_env", "agents", "benchmarks")
HISTORY_PAGES = ("changelog.md",)
"""Pages that may speak of the project's history: the changelog, which shows CHANGELOG.md as it was
written (its maths included); the checks skip it."""
NOT_YET_CONVERTED: tuple[str, ...] = ()
"""Pages and modules (path prefixes from the repository's root) the checks skip while they are
being converted: none, every page and module is checked. Add an entry only for the time a
conversion takes, and remove it when its files are converted."""

# The paper's notation written as code: each alternative is something that only a formula has.
MATHS_IN_CODE = re.compile(
    r"""
      [A-Za-z]_\{                          # a braced subscript: R_{k+1|k}
    | \^\{ | [\w)}]\^[\w(]                 # a power: e^{-x}, v_e^2, L^3
    | (?<![\w.])sum_(?:[a-z]\b|\{)         # a sum: sum_i R_i
    | (?<![\w.])(?:sqrt|abs|exp|log1p)\([^)]*\b(?:epsilon|sigma|Sigma|lambda|[a-z]_\w)  # sqrt(sigma_x)
    | (?<![\w.])(?:epsilon|sigma|beta|rho)\s+[A-Za-z](?:_\w+)?\b(?![=(.\[:])  # a product: beta c_k
    | (?<![\w.])[EP]\[ | (?<![\w.])P\(     # an expectation or a probability: E[I_C s], P(C_k)
    | \|\|\S[^|]*\|\|                      # a norm: ||e||
    | (?<![\w.])[A-Z]_[A-Za-z0-9]\b        # a symbol with a subscript: I_C, Z_x
    | (?<![\w.])[a-z]_[a-z0-9](?:,\w+)?\s+[-+*/<>=]|[-+*/<>=]\s+[a-z]_[a-z0-9]\b(?![.(\[])  # q_e - q_o
    | (?<![\w.])(?:epsilon|sigma|Sigma|lambda|omega|beta)(?:_\w+)?\s*(?:[-+*/<>]|<=|>=|\s=\s)  # epsilon <=
    | (?:\s[-+*/]|<=|>=|\s=\s)\s*(?:epsilon|sigma|Sigma|lambda|beta)\b(?!\s*[=,(\[])  # ... <= epsilon
    | (?<![\w.])[a-z]\s*(?:<=|>=)\s*[-\w]  # v >= 0
    """,
    re.VERBOSE,
)
# The paper's notation written as plain text in prose: braced subscripts, powers and sums only.
MATHS_AS_TEXT = re.compile(r"[A-Za-z]_\{|\^\{|(?<![\w.`])sum_(?:[a-z]\b|\{)")
HISTORY = re.compile(
    r"""
      \bissues?\s*\#?\d+ | \bissue'?s\b | \bthe\s+issue\b | \bPR\s*\#?\d+ | \bpull\s+request
    | \b(?<!unused\s)(?<!both\s)(?<!either\s)branch(?:es)?\b(?!\s+of\b)
    | \bsessions?\b | \bhelpers?\b | \bcommit\s+[0-9a-f]{7,}\b
    | \b(?:before|since|in)\s+this\s+version\b | \bthe\s+(?:previous|last)\s+version\b | \bpreviously\b
    """,
    re.VERBOSE | re.IGNORECASE,
)
CODE_SPAN = re.compile(r"(?<!`)(`+)(?!`)((?:(?!\n[ \t]*\n).)+?)(?<!`)\1(?!`)", re.DOTALL)
ROLE = re.compile(r":[a-z]+:`[^`]*`")
FENCE = re.compile(r"^(\s*)(```+|~~~+)([^\n]*)\n.*?^\1\2[ \t]*$", re.MULTILINE | re.DOTALL)
MATHS = re.compile(r"\$\$.+?\$\$|(?<![\\$])\$(?=\S)(?:\\.|[^$\\])+?(?<=\S)\$", re.DOTALL)
SNIPPET = re.compile(r'^--8<-- "([^":]+)[^"]*"$', re.MULTILINE)
HELP_KEYWORDS = ("help", "description", "epilog")


def relative(path: Path) -> str:
    return path.resolve().relative_to(ROOT).as_posix()


def in_scope(path: Path, everything: bool = False) -> bool:
    return path.name not in HISTORY_PAGES and (everything or not relative(path).startswith(NOT_YET_CONVERTED))


def pages(everything: bool = False) -> list[Path]:
    """The docs pages in scope (``everything``: the ones not yet converted too)."""
    found = [p for p in DOCS.rglob("*.md") if "results" not in p.relative_to(DOCS).parts]
    return sorted(p for p in found if in_scope(p, everything))


def modules(everything: bool = False) -> list[Path]:
    """The modules whose docstrings the API pages render (in scope)."""
    found = [p for top in SOURCES for p in (ROOT / top).rglob("*.py")]
    return sorted(p for p in found if in_scope(p, everything))


def included(page: Path) -> list[Path]:
    """The results files ``page`` includes (benchmarks write them; fix the writer, not the file)."""
    files = [DOCS / "results" / target for target in SNIPPET.findall(page.read_text())]
    return [f for f in files if f.suffix == ".md" and f.is_file()]


def _strings(node: ast.AST) -> str | None:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(
            v.value for v in node.values if isinstance(v, ast.Constant) and isinstance(v.value, str)
        )
    return None


def docstrings(path: Path) -> Iterator[tuple[int, str, bool]]:
    """``(line, text, is_help)`` for every docstring of ``path`` (module, class, function and
    attribute docstrings) and every ``help``/``description``/``epilog`` text of its command line."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list):
            for i, stmt in enumerate(body):
                first = i == 0 and isinstance(
                    node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
                )
                after_assignment = i > 0 and isinstance(body[i - 1], (ast.Assign, ast.AnnAssign))
                if isinstance(stmt, ast.Expr) and (first or after_assignment):
                    if (text := _strings(stmt.value)) is not None:
                        yield stmt.lineno, text, False
        if isinstance(node, ast.Call):
            for keyword in node.keywords:
                if keyword.arg in HELP_KEYWORDS and (text := _strings(keyword.value)) is not None:
                    yield keyword.value.lineno, text, True


def markdown_prose(text: str) -> str:
    """``text`` without fenced code blocks, HTML comments and snippet lines."""
    text = FENCE.sub("", text)
    text = re.sub(r"<!--.*?-->", "", text, flags=re.DOTALL)
    return SNIPPET.sub("", text)


def _blank(match: re.Match[str]) -> str:
    """``match`` as spaces, its newlines kept (so that offsets still give lines)."""
    return re.sub(r"[^\n]", " ", match.group(0))


def _line(text: str, offset: int, first: int) -> int:
    return first + text.count("\n", 0, offset)


def problems(text: str, first_line: int = 1, *, maths: bool = True, history: bool = True) -> Iterator[str]:
    """What is wrong in one piece of docs text (markdown or a docstring): maths shown as code or as
    plain text, and words of the project's history. Each as ``line: kind: excerpt``."""
    text = ROLE.sub("ROLE", text)
    if maths:
        for span in CODE_SPAN.finditer(text):
            code = span.group(2)
            if not code.lstrip().startswith(("python ", "pip ", "--", "-m ")) and MATHS_IN_CODE.search(code):
                yield f"{_line(text, span.start(), first_line)}: maths as code: {span.group(0)}"
        prose = MATHS.sub(_blank, CODE_SPAN.sub(_blank, text))
        for found in MATHS_AS_TEXT.finditer(prose):
            excerpt = prose[max(0, found.start() - 20) : found.end() + 20].replace("\n", " ")
            yield f"{_line(text, found.start(), first_line)}: maths as text: ...{excerpt}..."
    if history:
        for found in HISTORY.finditer(text):
            excerpt = text[max(0, found.start() - 30) : found.end() + 30].replace("\n", " ")
            yield f"{_line(text, found.start(), first_line)}: history: ...{excerpt}..."


def findings(everything: bool = False, paths: list[Path] | None = None) -> dict[str, list[str]]:
    """Every problem in the pages and modules in scope (``everything``: in all of them; ``paths``:
    in these only), by file."""
    out: dict[str, list[str]] = {}
    for page in pages(everything) if paths is None else [p for p in paths if p.suffix == ".md"]:
        history = page.name not in HISTORY_PAGES
        found = list(problems(markdown_prose(page.read_text()), history=history))
        for result in included(page):
            found += [
                f"{relative(result)}:{p}"
                for p in problems(markdown_prose(result.read_text()), history=history)
            ]
        if found:
            out[relative(page)] = found
    for module in modules(everything) if paths is None else [p for p in paths if p.suffix == ".py"]:
        found = []
        for line, text, is_help in docstrings(module):
            # --help texts show on the site as plain text, where no maths can render
            found += problems(text, line, maths=not is_help)
        if found:
            out[relative(module)] = found
    return out


def test_maths_is_configured():
    yaml = pytest.importorskip("yaml")
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text().replace("!!python", "#"))
    extensions = [e if isinstance(e, str) else next(iter(e)) for e in config["markdown_extensions"]]
    arithmatex = next(
        e for e in config["markdown_extensions"] if isinstance(e, dict) and "pymdownx.arithmatex" in e
    )
    assert arithmatex["pymdownx.arithmatex"] == {"generic": True}
    assert extensions.index("pymdownx.arithmatex") < extensions.index("pymdownx.superfences")
    scripts = config["extra_javascript"]
    assert "javascripts/mathjax.js" in scripts and (DOCS / "javascripts" / "mathjax.js").is_file()
    assert any("mathjax" in s and s.startswith("https://") for s in scripts)


@pytest.mark.parametrize("path", [relative(p) for p in pages() + modules()])
def test_the_docs_typeset_maths_and_speak_no_history(path):
    found = findings(paths=[ROOT / path]).get(path, [])
    assert not found, f"{path}:\n" + "\n".join(found)


HEADING = re.compile(r'<h[12] id="((?:risk_env|agents|benchmarks)[\w.]*)" class="doc doc-heading')
TAG = re.compile(r"<[^>]+>")
PRE = re.compile(r"<pre\b.*?</pre>", re.DOTALL)
INLINE_CODE = re.compile(r"<code>(.*?)</code>", re.DOTALL)


def _source(identifier: str) -> str | None:
    """The file that defines the documented object ``identifier`` (None: not one of ours)."""
    import pydoc

    path = identifier.replace(".", "/")
    for candidate in (f"{path}.py", f"{path}/__init__.py"):
        if (ROOT / candidate).is_file():
            return candidate
    module = getattr(pydoc.locate(identifier), "__module__", None)
    return _source(module) if module and module != identifier else None


def rendered_sections(site: Path) -> Iterator[tuple[str, str]]:
    """``(source, html)`` of every page of a built site, split where it renders a module or an
    object (``source``: the page's path, or the defining module's, as in :data:`NOT_YET_CONVERTED`)."""
    for html in sorted(site.rglob("index.html")):
        page = html.parent.relative_to(site).as_posix()
        text = html.read_text()
        text = text[text.find("<article") : text.find("</article>")]
        cuts = [(m.start(), source) for m in HEADING.finditer(text) if (source := _source(m.group(1)))]
        starts = [0, *(c for c, _ in cuts), len(text)]
        names = [f"docs/{page or 'index'}.md", *(source for _, source in cuts)]
        for name, start, end in zip(names, starts, starts[1:]):
            yield name, text[start:end]


@pytest.mark.slow
def test_the_built_site_typesets_maths_and_speaks_no_history(tmp_path):
    """Builds the site (about a minute) and reads its HTML: maths typeset on the pages and in the
    docstrings, none shown as code, no history outside the changelog."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
    )
    assert build.returncode == 0, build.stderr[-3000:]
    sections: dict[str, str] = {}
    for source, html in rendered_sections(tmp_path):
        sections[source] = sections.get(source, "") + html
    assert '<span class="arithmatex">' in sections["docs/risk.md"]
    assert '<div class="arithmatex">' in sections["risk_env/risk/total_risk.py"]
    found = []
    for source, html in sections.items():
        if not in_scope(ROOT / source):
            continue
        for code in INLINE_CODE.findall(PRE.sub("", html)):
            code = unescape(TAG.sub("", code))
            if MATHS_IN_CODE.search(code) and not code.startswith(("python ", "pip ", "--")):
                found.append(f"{source}: maths as code: {code}")
        text = unescape(TAG.sub(" ", html))
        found += [f"{source}: history: {m.group(0)}" for m in HISTORY.finditer(text)]
    assert not found, "\n".join(found)


if __name__ == "__main__":  # the tool: list what the checks find
    args = [a for a in sys.argv[1:] if a != "--all"]
    paths = [Path(a).resolve() for a in args] or None
    for file, found in findings("--all" in sys.argv[1:], paths).items():
        print(f"== {file}")
        print("\n".join(f"  {f}" for f in found))
