"""MkDocs hooks for hdid's site (loaded by mkdocs.yml).

``<!-- hdid-schema: NAME -->`` in a page becomes the table of every field of the JSON
Schema ``src/hdid/schema/NAME.schema.json`` (the one the package ships and the tests
validate against), with its type, whether it is always present, and its description:
the field reference is generated from the schema, so it cannot drift from it.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

SCHEMAS = Path(__file__).resolve().parents[1] / "src" / "hdid" / "schema"
MARKER = re.compile(r"<!--\s*hdid-schema:\s*([\w-]+)\s*-->")


def _type(spec: dict) -> str:
    if "const" in spec:
        return f"`{json.dumps(spec['const'])}`"
    if "enum" in spec:
        return " \\| ".join(f"`{json.dumps(v)}`" for v in spec["enum"])
    kind = spec.get("type")
    if kind is None:
        return "any" if not spec.get("anyOf") and not spec.get("oneOf") else " \\| ".join(
            _type(s) for s in spec.get("anyOf", spec.get("oneOf", []))
        )
    kinds = kind if isinstance(kind, list) else [kind]
    if "array" in kinds and isinstance(spec.get("items"), dict) and spec["items"].get("type"):
        inner = spec["items"]["type"]
        inner = "/".join(inner) if isinstance(inner, list) else inner
        kinds = [f"array of {inner}" if k == "array" else k for k in kinds]
    return " or ".join(kinds)


def _cell(text: str) -> str:
    # [a] [b] or [a][b] would read as a Markdown reference link: escape the brackets
    # outside code spans (the odd pieces between backticks are code)
    parts = text.replace("|", "\\|").replace("\n", " ").split("`")
    for i in range(0, len(parts), 2):
        parts[i] = parts[i].replace("[", "\\[").replace("]", "\\]")
    return "`".join(parts)


def _rows(props: dict, required: set, prefix: str, depth: int) -> list[str]:
    rows = []
    for name, spec in props.items():
        path = f"{prefix}{name}"
        rows.append(
            f"| `{path}` | {_type(spec)} | {'yes' if name in required else ''} "
            f"| {_cell(spec.get('description', ''))} |"
        )
        if depth == 0:
            continue
        inner = spec
        suffix = "."
        if spec.get("type") == "array" or "array" in (spec.get("type") or []):
            inner, suffix = spec.get("items") or {}, "[]."
        elif "additionalProperties" in spec and isinstance(spec["additionalProperties"], dict):
            inner, suffix = spec["additionalProperties"], ".<name>."
        if isinstance(inner, dict) and inner.get("properties"):
            rows += _rows(inner["properties"], set(inner.get("required", [])), path + suffix, depth - 1)
    return rows


def schema_table(name: str) -> str:
    schema = json.loads((SCHEMAS / f"{name}.schema.json").read_text(encoding="utf-8"))
    head = [
        f"*{_cell(schema.get('description', ''))}* (`hdid/schema/{name}.schema.json`)",
        "",
        "| field | type | always | meaning |",
        "|---|---|---|---|",
    ]
    return "\n".join(head + _rows(schema.get("properties", {}), set(schema.get("required", [])), "", 1))


def _schema_tables(markdown: str) -> str:
    return MARKER.sub(lambda m: schema_table(m.group(1)), markdown)


ROOT = Path(__file__).resolve().parents[1]
LAYERS_MARKER = "<!-- hdid-layers -->"


def _first_line(path: Path) -> str:
    import ast

    try:
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    except SyntaxError:
        return ""
    line = doc.strip().split("\n\n")[0].replace("\n", " ").replace("``", "`")
    return re.sub(r":\w+:`~?\.?([^`]+)`", r"`\1`", line)


def layers_table() -> str:
    """The layers of ``tests/test_layers.py`` (its ``LAYERS``: one comment line, then one
    set of top-level names per layer, lowest first), each module with its docstring's
    first paragraph, read from ``src/hdid`` at build time."""
    import ast

    text = (ROOT / "tests" / "test_layers.py").read_text(encoding="utf-8")
    block = text[text.index("LAYERS = [") : text.index("\n]", text.index("LAYERS = ["))]
    pairs = re.findall(r"#\s*(.+)\n\s*(\{[^}]*\})", block)
    src = ROOT / "src" / "hdid"
    rows = ["| layer | module | what it does |", "|---|---|---|"]
    for n, (comment, names) in enumerate(pairs):
        label = f"{n}: {_cell(comment)}"
        for top in sorted(ast.literal_eval(names)):
            path = src / top
            files = (
                [path / "__init__.py", *sorted(p for p in path.glob("*.py") if p.name != "__init__.py")]
                if path.is_dir()
                else [src / f"{top}.py"]
            )
            for f in files:
                if not f.exists():
                    continue
                name = f.relative_to(src).with_suffix("").as_posix().replace("/__init__", "/")
                rows.append(f"| {label} | `{name}` | {_cell(_first_line(f))} |")
                label = ""
    return "\n".join(rows)




def on_config(config, **kwargs):
    """Append the decision records to the nav: ``decisions/index.md`` first, then every
    other ``decisions/*.md`` in name order (titles from their first heading)."""
    folder = Path(config["docs_dir"]) / "decisions"
    pages = sorted(folder.glob("*.md")) if folder.is_dir() else []
    if not pages:
        return config
    index = [p for p in pages if p.name == "index.md"]
    records = [p.relative_to(config["docs_dir"]).as_posix() for p in index + [p for p in pages if p.name != "index.md"]]
    config["nav"].append({"Decisions": records})
    return config


HELP_MARKER = "<!-- hdid-cli-help -->"


def cli_help() -> str:
    """``hdid --help`` and every ``hdid COMMAND --help``, as a terminal 88 columns wide
    shows them (the option groups included), each under its own heading."""
    from click.testing import CliRunner

    from hdid.cli import main

    def text(*args: str) -> str:
        result = CliRunner().invoke(main, [*args, "--help"], terminal_width=88, prog_name="hdid")
        if result.exit_code != 0:
            raise RuntimeError(f"hdid {' '.join(args)} --help failed: {result.output}")
        return result.output.rstrip()

    parts = ["### `hdid`", "", "```text", text(), "```"]
    for name in sorted(main.commands):
        parts += ["", f"### `hdid {name}`", "", "```text", text(name), "```"]
    return "\n".join(parts)


def on_page_markdown(markdown: str, **kwargs) -> str:
    """MkDocs hook: every generated block (schema tables, layer table, CLI help)."""
    markdown = _schema_tables(markdown)
    for marker, make in ((LAYERS_MARKER, layers_table), (HELP_MARKER, cli_help)):
        if marker in markdown:
            markdown = markdown.replace(marker, make())
    return markdown
