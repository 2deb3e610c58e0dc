"""The docs site: every public name in the API reference, every include and marker resolves, every
anchor the benchmarks point to exists, and every Python block runs alone. (``mkdocs build --strict``
in ``.ci/run`` renders the whole site.)"""

from __future__ import annotations

import importlib
import importlib.util
import re
import sys
from pathlib import Path

import doc_blocks  # tests/doc_blocks.py
import pytest

from benchmarks import summary

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PAGES = doc_blocks.doc_pages()
API_PAGES = ("risk_env.md", "highway.md", "agents.md", "benchmarks.md")
API = "\n".join((DOCS / "api" / name).read_text() for name in API_PAGES)
PACKAGES = ("risk_env", "risk_env.highway", "agents")
SNIPPET = re.compile(r'^--8<-- "([^"]+)"$', re.MULTILINE)


@pytest.fixture(scope="module")
def hooks():
    """docs/hooks.py, the build's table generators."""
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["docs_hooks"] = module
    spec.loader.exec_module(module)
    return module


def rendered_modules() -> set[str]:
    return set(re.findall(r"^::: ([\w.]+)$", API, flags=re.MULTILINE))


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_is_in_the_api_reference(package, hooks):
    exported = hooks.exported(package)
    if package != "risk_env.highway" or importlib.util.find_spec("highway_env") is not None:
        assert set(exported) == set(importlib.import_module(package).__all__)
    assert f"<!-- public-names {package} -->" in API
    table = hooks.public_names(package)
    for name, module in exported.items():
        assert f"[`{name}`][{module}.{name}]" in table
        assert module in rendered_modules(), f"{package}.{name} is defined in {module}, not in the API pages"


def test_every_module_has_an_api_page():
    modules = {
        ".".join(path.relative_to(ROOT).with_suffix("").parts)
        for top in ("risk_env", "agents", "benchmarks")
        for path in (ROOT / top).rglob("*.py")
        if not path.name.startswith("_")
    }
    assert modules - rendered_modules() == set()


def test_every_page_is_in_the_nav():
    yaml = pytest.importorskip("yaml")
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text().replace("!!python", "#"))

    def pages(node):
        if isinstance(node, str):
            yield node
        elif isinstance(node, list):
            for item in node:
                yield from pages(item)
        elif isinstance(node, dict):
            for value in node.values():
                yield from pages(value)

    assert {p.relative_to(DOCS).as_posix() for p in PAGES} == set(pages(config["nav"]))


def test_every_marker_expands(hooks):
    for page in PAGES:
        text = page.read_text()
        expanded = hooks.expand(text)
        assert "<!-- scenario-fields" not in expanded and "<!-- cli-help" not in expanded


def test_the_scenario_table_has_every_override(hooks):
    from risk_env.scenario.scenario import OVERRIDES

    table = hooks.scenario_fields()
    for name in OVERRIDES:
        assert f"| `{name}` |" in table
    assert table.count("\n") == len(OVERRIDES) + 1


def test_every_snippet_include_resolves():
    for page in PAGES:
        for target in SNIPPET.findall(page.read_text()):
            path, _, section = target.partition(":")
            file = next((b / path for b in (DOCS / "results", ROOT) if (b / path).is_file()), None)
            assert file is not None, f"{page.name} includes a missing {path}"
            if section and not section[0].isdigit():
                text = file.read_text()
                assert f"[start:{section}]" in text and f"[end:{section}]" in text, f"{target} in {page.name}"


def headings(page: Path) -> set[str]:
    from markdown.extensions.toc import slugify

    return {slugify(h, "-") for h in re.findall(r"^#+ (.+)$", page.read_text(), flags=re.MULTILINE)}


def test_the_anchors_the_benchmarks_point_to_exist():
    pytest.importorskip("markdown")
    for link in [summary.DOCS + anchor for anchor in summary.ANCHORS.values()] + [summary.FALLBACK_DOCS]:
        path, anchor = link.split("#")
        assert anchor in headings(ROOT / path), f"{link} does not exist"


def test_internal_links_between_pages_resolve():
    pytest.importorskip("markdown")
    for page in PAGES:
        for target, anchor in re.findall(r"\]\(([\w./-]+\.md)(?:#([\w-]+))?\)", page.read_text()):
            linked = (page.parent / target).resolve()
            assert linked.is_file(), f"{page.name} links to a missing {target}"
            if anchor:
                assert anchor in headings(linked), f"{page.name} links to a missing {target}#{anchor}"


DOC_BLOCKS = [pytest.param(code, id=name) for name, code in doc_blocks.docs_python_blocks().items()]


@pytest.mark.parametrize("code", DOC_BLOCKS)
def test_every_python_block_of_the_docs_runs_alone(code, blocks_run_alone):
    """As the README's blocks: each as if alone, in this interpreter (tests/doc_blocks.py)."""
    if (module := doc_blocks.missing_extra(code)) is not None:
        pytest.skip(f"the block needs {module} (an optional extra)")
    result = blocks_run_alone[code]
    assert result.returncode == 0, result.stderr[-3000:]


@pytest.mark.slow  # one interpreter per block; test_every_python_block_of_the_docs_runs_alone is the fast one
@pytest.mark.parametrize("code", DOC_BLOCKS)
def test_every_python_block_of_the_docs_runs_alone_in_a_fresh_interpreter(code, tmp_path):
    if (module := doc_blocks.missing_extra(code)) is not None:
        pytest.skip(f"the block needs {module} (an optional extra)")
    result = doc_blocks.run_alone(code, tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]


def test_citation_metadata():
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["license"] == "MIT"
    paper = cff["references"][0]
    assert [a["family-names"] for a in paper["authors"]] == ["Tolksdorf", "Tejada", "van de Wouw", "Birkner"]
    assert "arXiv:2304.12063" in [i["value"] for i in paper["identifiers"]]
    assert "RiskCrossing contributors" in (ROOT / "LICENSE").read_text()
