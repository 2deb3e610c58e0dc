"""MkDocs hooks: tables that the docs generate from the code and from the files it writes.

A page asks for one with an HTML comment on a line of its own; :func:`on_page_markdown` replaces it:

- ``<!-- scenario-fields -->``: every field of :class:`risk_env.Scenario`, by its flat override
  name, with its default and the docstring under it;
- ``<!-- uncertainty-presets -->``: the paper's Table I, from
:meth:`risk_env.scenario.scenario.Uncertainty.preset`;
- ``<!-- public-names PACKAGE -->``: every name of ``PACKAGE.__all__``, linked to its documentation;
- ``<!-- cli-help NAME -->``: the ``--help`` of ``python -m benchmarks.NAME``;
- ``<!-- ppo-training -->``: the shipped PPO policies' training record (``agents/models/*.json``);
- ``<!-- collided-runs DIR -->``: the runs of ``docs/results/DIR/table2.csv`` (``.`` for
  ``docs/results``) that collided, with the largest risk the env reported in each.

An unknown marker fails the build, so a misspelt one cannot go unnoticed.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import json
import os
import re
import sys
import textwrap
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path[:1]:
    sys.path.insert(0, str(ROOT))  # document this checkout, whatever else is installed
MARKER = re.compile(r"^<!-- ([a-z-]+)(?: ([\w.]+))? -->$", re.MULTILINE)
HELP_COLUMNS = "100"
"""Terminal width the ``--help`` texts are formatted for."""


def attribute_docs(cls: type) -> dict[str, str]:
    """The docstring under each annotated attribute of ``cls`` (dataclass fields), one line each."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, after in zip(body, body[1:]):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant):
                docs[node.target.id] = " ".join(str(after.value.value).split())
    return docs


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _default(value: Any) -> str:
    if dataclasses.is_dataclass(value):
        return "(" + ", ".join(f"{getattr(value, f.name):g}" for f in dataclasses.fields(value)) + ")"
    if isinstance(value, tuple):
        return "(" + ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value) + ")"
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value) if isinstance(value, str) else str(value)


def scenario_fields() -> str:
    """Markdown table of every Scenario field: flat name, field, default, meaning."""
    from risk_env.scenario.scenario import OVERRIDES, Scenario

    flat = {(part, attr): name for name, (part, attr) in OVERRIDES.items()}
    default = Scenario()
    rows = ["| keyword | field | default | meaning |", "| --- | --- | --- | --- |"]
    for field in dataclasses.fields(Scenario):
        value = getattr(default, field.name)
        if field.name == "objects":  # the list, then the first object's fields by their flat names
            docs = attribute_docs(Scenario)
            meaning = _cell(docs.get("objects", ""))
            rows.append(f"| `objects` | `objects` | the paper's one object | {meaning} |")
            first = value[0]
            docs = attribute_docs(type(first))
            for sub in dataclasses.fields(first):
                if ("object", sub.name) in flat:
                    rows.append(
                        f"| `{flat[('object', sub.name)]}` | `objects[0].{sub.name}` |"
                        f" `{_default(getattr(first, sub.name))}` | {_cell(docs.get(sub.name, ''))} |"
                    )
        elif dataclasses.is_dataclass(value):
            docs = attribute_docs(type(value))
            for sub in dataclasses.fields(value):
                name = flat.get((field.name, sub.name), "")
                rows.append(
                    f"| `{name}` | `{field.name}.{sub.name}` | `{_default(getattr(value, sub.name))}` |"
                    f" {_cell(docs.get(sub.name, ''))} |"
                )
        else:
            docs = attribute_docs(Scenario)
            name = flat.get((None, field.name), "")
            rows.append(
                f"| `{name}` | `{field.name}` | `{_default(value)}` | {_cell(docs.get(field.name, ''))} |"
            )
    return "\n".join(rows)


def uncertainty_presets() -> str:
    """The paper's Table I as the presets build it."""
    from risk_env.scenario.scenario import UNCERTAINTY_PRESETS, Uncertainty

    rows = [
        "| level | Q: sigma growth per step (c1 [m], c2 [m], v [m/s])"
        " | Delta: box growth per step and side |",
        "| --- | --- | --- |",
    ]
    for level in UNCERTAINTY_PRESETS:
        u = Uncertainty.preset(level)
        rows.append(f"| `{level}` | `{_default(u.sigma_growth)}` | `{_default(u.box_growth)}` |")
    return "\n".join(rows)


def exported(package: str) -> dict[str, str]:
    """``{name: module it is defined in}`` for each name of ``package.__all__``, from the source."""
    init = ROOT / package.replace(".", "/") / "__init__.py"
    tree = ast.parse(init.read_text())
    origin: dict[str, str] = {}
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(package.split(".")[0]):
            for alias in node.names:
                origin[alias.asname or alias.name] = node.module
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            names = list(ast.literal_eval(node.value))
    return {name: origin.get(name, package) for name in names}


def public_names(package: str) -> str:
    """Markdown table of ``package.__all__``: each name linked to its module's documentation."""
    rows = ["| name | defined in |", "| --- | --- |"]
    for name, module in sorted(exported(package).items(), key=lambda item: item[0].lower()):
        rows.append(f"| [`{name}`][{module}.{name}] | [`{module}`][{module}] |")
    return "\n".join(rows)


def cli_help(name: str) -> str:
    """``python -m benchmarks.NAME --help`` as a text block."""
    module = importlib.import_module(f"benchmarks.{name}")
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        text = module.build_parser().format_help()
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous
    return f"```text\n$ python -m benchmarks.{name} --help\n{text.rstrip()}\n```"


def ppo_training() -> str:
    """The shipped policies' training record, from ``agents/models/*.json``."""
    rows = [
        "| policy | env steps | wall time [s] | env steps/s incl. updates | last rollout: episode cost"
        " / collisions / goal | beta at the end |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for path in sorted((ROOT / "agents" / "models").glob("*.json")):
        if path.stem.endswith("_seeds") or path.name.endswith(".manifest.json"):
            continue  # the seeds' training times (below their shipped policy); output manifests
        meta = json.loads(path.read_text())
        last = meta.get("final_rollout", {})
        args = meta["args"]
        nan = float("nan")
        beta, cost = last.get("beta", nan), last.get("episode_cost", nan)
        collisions, goal = 100 * last.get("collision", nan), 100 * last.get("is_success", nan)
        how = "dual ascent" if args.get("lagrangian") else "fixed"
        rows.append(
            f"| `{path.stem}` | {meta['timesteps']:,} | {meta['wall_time_s']:.1f} |"
            f" {meta['steps_per_s']:,.0f} | {cost:.3f} / {collisions:.1f} % / {goal:.0f} % |"
            f" {beta:.0f} ({how}) |"
        )
        seeds = path.with_name(f"{path.stem}_seeds.json")
        if seeds.is_file():
            for seed, t in json.loads(seeds.read_text())["training"].items():
                rows.append(
                    f"| `{path.stem}`, seed {seed} | {meta['timesteps']:,} | {t['wall_time_s']:.1f} |"
                    f" {t['steps_per_s']:,.0f} | | |"
                )
    return "\n".join(rows)


def collided_runs(folder: str) -> str:
    """The collided runs of a Table II CSV: agent, level, epsilon, the largest reported risk, d_min."""
    import csv

    path = ROOT / "docs" / "results" / folder / "table2.csv"
    with path.open() as f:
        rows = [r for r in csv.DictReader(f) if r["collided"] == "True"]
    unit = "" if rows and rows[0]["severity"] == "probability" else " [J]"
    out = [
        f"| agent | uncertainty | epsilon{unit} | largest reported risk{unit} | d_min [m] | steps |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        out.append(
            f"| {r.get('agent') or r['method'].lower() + ':' + r['risk_method']} | {r['uncertainty']} |"
            f" {float(r['epsilon']):g} |"
            f" {float(r['max_risk']):.1f} | {float(r['d_min']):.2f} | {r['steps']} |"
        )
    if not rows:
        out.append("| (none) | | | | | |")
    return "\n".join(out)


GENERATORS = {
    "scenario-fields": lambda arg: scenario_fields(),
    "uncertainty-presets": lambda arg: uncertainty_presets(),
    "public-names": public_names,
    "cli-help": cli_help,
    "ppo-training": lambda arg: ppo_training(),
    "collided-runs": collided_runs,
}


def expand(markdown: str) -> str:
    """``markdown`` with every marker replaced by its generated table (unknown markers raise)."""

    def replace(match: re.Match[str]) -> str:
        kind, arg = match.group(1), match.group(2)
        if kind not in GENERATORS:
            raise ValueError(f"unknown docs marker {match.group(0)!r}; expected one of {sorted(GENERATORS)}")
        return GENERATORS[kind](arg)

    return MARKER.sub(replace, markdown)


def on_page_markdown(markdown: str, **kwargs: Any) -> str:
    """MkDocs hook: expand the markers of every page."""
    return expand(markdown)
