"""Pages generated from the project's own sources at every build, never copied by hand.

- ``generated/scene-keys.md``: every scene key with its type, unit, default and bounds,
  from the scene schema (:func:`softbody.scenes.scene_json_schema`).
- ``generated/cli.md``: every command and option, from the argument parser
  (:func:`softbody.cli.build_parser`).
- ``generated/benchmarks/*.md``: one page per ``benchmarks/results/*.json`` with its
  plot, date, machine and command, and the notes in ``docs/benchmarks/notes/NAME.md``.
- ``generated/benchmark-summary.md``: the benchmarks index's table of headline figures,
  from ``benchmarks/results/summary.json`` (``benchmarks/summary.py``), and its plot.
- ``generated/integrator-table.md``: the integrator decision table, from the ball-drop
  benchmarks' JSON.
- ``generated/verification.md``: every test with its docstring (its reference and
  tolerance), from ``tests/test_*.py``.

The folder ``docs/generated`` is rewritten at each build (and ignored by git).
"""

from __future__ import annotations

import argparse
import ast
import json
import shutil
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
OUT = DOCS / "generated"
RESULTS = ROOT / "benchmarks" / "results"
MACHINE = "the project's machine: 2-core AMD EPYC (Zen 4), shared with other jobs and noisy"


def _write(path: Path, text: str) -> None:
    """Write only when the text changed, so that Sphinx rebuilds only what changed."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def _cell(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


# -- scene keys -------------------------------------------------------------------------
def _type(prop: dict, defs: dict) -> str:
    if "$ref" in prop:
        name = prop["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#scene-{name.lower()})"
    if "anyOf" in prop or "oneOf" in prop:
        parts = [_type(p, defs) for p in prop.get("anyOf", prop.get("oneOf", []))]
        return " or ".join(dict.fromkeys(p for p in parts if p != "null")) + (
            " (optional)" if any(p.get("type") == "null" for p in prop.get("anyOf", [])) else ""
        )
    if "const" in prop:
        return f'`"{prop["const"]}"`'
    if "enum" in prop:
        return "one of " + ", ".join(f'`"{v}"`' for v in prop["enum"])
    kind = prop.get("type", "value")
    if kind == "array":
        items = prop.get("prefixItems")
        if items:
            return f"array of {len(items)} {_type(items[0], defs)}"
        if "items" in prop:
            return f"array of {_type(prop['items'], defs)}"
        return "array"
    return {"number": "number", "integer": "integer", "string": "string", "boolean": "boolean",
            "object": "table"}.get(kind, str(kind))  # fmt: skip


def _bounds(prop: dict) -> str:
    found = []
    for p in [prop, *prop.get("anyOf", [])]:
        for key, sign in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="),
                          ("exclusiveMaximum", "<"), ("minLength", "length >="),
                          ("maxLength", "length <="), ("minItems", "items >="),
                          ("pattern", "matches")):  # fmt: skip
            if key in p:
                found.append(f"{sign} `{p[key]}`")
    return ", ".join(dict.fromkeys(found))


def scene_keys() -> str:
    from softbody.scenes import scene_json_schema

    schema = scene_json_schema()
    defs = schema.get("$defs", {})
    lines = [
        "# Scene keys",
        "",
        "Generated from the scene schema (`softbody.scenes.SceneSpec`) at build time; "
        "`softbody scenes --schema` prints the same schema as JSON Schema for editors. "
        "Units are in brackets. A key not listed here is an error naming the valid ones; "
        '`--set key=value` overrides any key by its dotted path (`bodies.0.gas.nrt=50`).',
        "",
    ]

    def table(title: str, anchor: str, node: dict) -> None:
        lines.extend([f"({anchor})=", f"## {title}", ""])
        if node.get("description"):
            lines.extend([node["description"], ""])
        required = set(node.get("required", []))
        lines.extend(["| key | type | default | bounds | meaning |", "|---|---|---|---|---|"])
        for key, prop in node.get("properties", {}).items():
            if key in required:
                default = "required"
            elif isinstance(prop.get("default"), dict):
                default = "its table's defaults"
            else:
                default = f"`{json.dumps(prop.get('default'))}`"
            lines.append(
                f"| `{key}` | {_cell(_type(prop, defs))} | {_cell(default)} | "
                f"{_cell(_bounds(prop))} | {_cell(prop.get('description', ''))} |"
            )
        lines.append("")

    table("The scene file (top level)", "scene-scenespec", schema)
    for name in sorted(defs):
        table(f"{name}", f"scene-{name.lower()}", defs[name])
    return "\n".join(lines)


# -- command line -----------------------------------------------------------------------
def _options(parser: argparse.ArgumentParser) -> list[str]:
    lines = ["| argument | default | meaning |", "|---|---|---|"]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction | argparse._HelpAction):
            continue
        name = ", ".join(f"`{o}`" for o in action.option_strings) or f"`{action.dest}`"
        if action.metavar and action.option_strings:
            name += f" `{action.metavar}`"
        default = "" if action.default in (None, False, argparse.SUPPRESS) else action.default
        lines.append(f"| {name} | {_cell(default)} | {_cell(action.help or '')} |")
    return [*lines, ""]


def cli_page() -> str:
    from softbody.cli import build_parser

    parser = build_parser()
    lines = ["# Command line", "", "Generated from `softbody.cli.build_parser()` at build time.",
             "", "```text", parser.format_help().rstrip(), "```", ""]  # fmt: skip
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                lines.extend([f"## softbody {name}", "", "```text",
                              sub.format_usage().strip(), "```", ""])  # fmt: skip
                if sub.description:
                    lines.extend([sub.description, ""])
                lines.extend(_options(sub))
    return "\n".join(lines)


# -- benchmarks -------------------------------------------------------------------------
def _script_doc(name: str) -> str:
    script = ROOT / "benchmarks" / f"{name}.py"
    if not script.exists():
        return ""
    return ast.get_docstring(ast.parse(script.read_text())) or ""


def benchmark_pages() -> list[str]:
    out = OUT / "benchmarks"
    out.mkdir(parents=True, exist_ok=True)
    names = []
    for path in sorted(RESULTS.glob("*.json")):
        name = path.stem
        if name == "summary":  # the index's table (benchmark_summary)
            continue
        data = json.loads(path.read_text())
        machine = data.get("machine")
        if isinstance(machine, dict):
            machine = ", ".join(f"{k} {v}" for k, v in machine.items())
        command = data.get("command") or f"python benchmarks/{name}.py"
        lines = [f"# {name.replace('_', ' ')}", "",
                 f"- **command:** `{command}` (writes `benchmarks/results/{name}.json`"
                 + (f" and `{name}.png`)" if (RESULTS / f"{name}.png").exists() else ")"),
                 f"- **date:** {data.get('date', 'not recorded')}",
                 f"- **machine:** {MACHINE}" + (f" (recorded: {machine})" if machine else ""),
                 f"- **cores seen:** {data.get('cores', 'not recorded')}", ""]  # fmt: skip
        if (RESULTS / f"{name}.png").exists():
            shutil.copyfile(RESULTS / f"{name}.png", out / f"{name}.png")
            lines.extend([f"![{name}]({name}.png)", ""])
        notes = DOCS / "benchmarks" / "notes" / f"{name}.md"
        if notes.exists():
            lines.extend(["```{include} ../../benchmarks/notes/" + f"{name}.md", "```", ""])
        doc = _script_doc(name)
        if doc:
            lines.extend(["## What the script measures", "", "```text", doc, "```", ""])
        lines.extend(["## The numbers", "",
                      "The whole result file, as the benchmark wrote it:", "",
                      "```{literalinclude} ../../../benchmarks/results/" + f"{name}.json",
                      ":language: json", "```", ""])  # fmt: skip
        _write(out / f"{name}.md", "\n".join(lines))
        names.append(name)
    return names


def benchmark_summary() -> str:
    """The headline figures as a Markdown table (and their plot copied beside the pages)."""
    summary = json.loads((RESULTS / "summary.json").read_text())
    shutil.copyfile(RESULTS / "summary.png", OUT / "benchmarks" / "summary.png")
    units = {"x real time": "{:.3g}x real time", "M vertex-steps/s": "{:.3g} M vertex-steps/s",
             "s": "{:.2g} s", "x Jolt's rate": "{:.3g}x Jolt's rate"}  # fmt: skip
    lines = ["| case | vertices | integrator | step | measured | check | from |",
             "|---|---:|---|---|---:|---|---|"]  # fmt: skip
    for row in summary["rows"]:
        lines.append("| " + " | ".join(_cell(c) for c in [
            row["case"], f"{row['vertices']:,}", row["integrator"], row["step"],
            units[row["unit"]].format(row["value"]), row["check"],
            f"`{row['source']}` ({row['date']}), `{row['command']}`",
        ]) + " |")  # fmt: skip
    lines.extend(["", f"Machine: {summary['machine']}. Written by `{summary['command']}` "
                  "from the result files named in each row; nothing is measured again.",
                  ""])  # fmt: skip
    return "\n".join(lines)


def integrator_table() -> str:
    drop = json.loads((RESULTS / "ball_drop.json").read_text())
    proj = json.loads((RESULTS / "projective_drop.json").read_text())
    lines = [
        f"Measured by `python benchmarks/ball_drop.py` ({drop['date']}) and "
        f"`python benchmarks/projective_drop.py` ({proj['date']}) on {MACHINE}, one thread. "
        "A 1 m, 1 kg inflated ball (k = 500 N/m per edge, nRT = 300 J) dropped from 1 m "
        "onto the ground; *step* is the step used (the explicit "
        "schemes at 0.9 of their estimated stable step), *ms/step* the cost of one step, "
        "*x real time* simulated over wall seconds when stepping, *rebound* the first "
        "bounce's height (m), *ok* whether the checked drop passed (volume within bounds, "
        "no blow-up); a dash where the checked drop was not run.",
        "",
        "| vertices | integrator | step (ms) | ms/step | x real time | rebound (m) | ok |",
        "|---:|---|---:|---:|---:|---:|---|",
    ]
    for size in drop["sizes"]:
        for name, run in size["integrators"].items():
            full = run.get("full_drop") or {}
            rebound = full.get("rebound_m")
            lines.append(
                f"| {size['vertex_count']:,} | {name} | {1e3 * run['dt_s']:.3g} | "
                f"{1e3 / run['steps_per_second']:.3g} | {run['simulated_per_wall_second']:.3g} | "
                f"{'-' if rebound is None else f'{rebound:.2f}'} | "
                f"{'-' if full.get('ok') is None else ('yes' if full['ok'] else 'no')} |"
            )
    lines.extend(["", "Projective dynamics on the same drop (final height: the ball's "
                  "centre after 2 s; backward Euler's is about 1.00 m, one radius):", "",
                  "| vertices | iterations | x real time | rebound (m) | final height (m) | ok |",
                  "|---:|---|---:|---:|---:|---|"])  # fmt: skip
    for size in proj["sizes"]:
        for name, run in size["runs"].items():
            full = run.get("full_drop") or {}
            if "simulated_per_wall_second" not in run:
                continue
            lines.append(
                f"| {size['vertex_count']:,} | {name} | {run['simulated_per_wall_second']:.3g} | "
                f"{full.get('rebound_m', float('nan')):.2f} | "
                f"{full.get('final_height_m', float('nan')):.2f} | "
                f"{'-' if full.get('ok') is None else ('yes' if full['ok'] else 'no')} |"
            )
    return "\n".join(lines) + "\n"


# -- verification -----------------------------------------------------------------------
def verification_page() -> str:
    lines = [
        "# Verification",
        "",
        "Every test of the suite with its docstring, which names the reference it is held "
        "to (a closed form, a conservation law, an energy gradient, a measured limit) and "
        "its tolerance. Generated at build time from `tests/test_*.py`; run them all with "
        "`python -m pytest`.",
        "",
    ]
    for path in sorted((ROOT / "tests").glob("test_*.py")):
        tree = ast.parse(path.read_text())
        module_doc = ast.get_docstring(tree) or ""
        tests = []
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name.startswith(
                "test"
            ):
                tests.append((node.lineno, node.name, ast.get_docstring(node) or ""))
        if not tests:
            continue
        lines.extend([f"## {path.name}", ""])
        if module_doc:
            lines.extend([_cell(module_doc), ""])
        for _, name, doc in sorted(tests):
            text = " ".join(doc.split()) if doc else "(no docstring)"
            lines.append(f"- **`{name}`**: {_escape(text)}")
        lines.append("")
    return "\n".join(lines)


def _escape(text: str) -> str:
    # docstrings are plain text: keep MyST from reading roles, targets or math in them
    for ch in ("*", "_", "`", "$", "[", "]", "<", ">", "{", "}"):
        text = text.replace(ch, "\\" + ch)
    return text


def generate(app=None) -> None:
    OUT.mkdir(exist_ok=True)
    _write(OUT / "scene-keys.md", scene_keys())
    _write(OUT / "cli.md", cli_page())
    _write(OUT / "integrator-table.md", integrator_table())
    _write(OUT / "verification.md", verification_page())
    benchmark_pages()
    _write(OUT / "benchmark-summary.md", benchmark_summary())


def setup(app):
    app.connect("builder-inited", generate)
    return {"parallel_read_safe": True, "parallel_write_safe": True, "version": "1"}
