"""Griffe extension for hdid's API pages (loaded by mkdocs.yml).

1. ``hdid/__init__.py`` exports its public names lazily (a ``_LAZY`` table of
   name → module read by ``__getattr__``). Static analysis sees only the names also
   imported under ``TYPE_CHECKING``; this adds every ``_LAZY`` name as an alias of its
   module's object, so ``::: hdid.NAME`` works for every export and a new export needs
   no edit here.
2. hdid's docstrings use Sphinx roles (``:func:`hdid.read_log```); Markdown shows those
   as plain code (``hdid.read_log``; a ``~`` keeps the last part only).
3. hdid's docstrings often close their ``Parameters`` list with an unindented paragraph
   (what the function guarantees, how it works). The numpy parser would read its words as
   parameter names; such a paragraph is rendered under ``Notes``. A documented parameter
   that the signature lacks still fails the strict build.
"""

from __future__ import annotations

import ast
import re

import griffe

_SECTION_WITH_ITEMS = {"Parameters", "Other Parameters", "Attributes"}
#: A numpy item line: ``name``, ``name:``, ``name : type``, ``a, b : type``, ``**kwargs``.
_ITEM = re.compile(r"^\*{0,2}\w+(\s*,\s*\*{0,2}\w+)*\s*(:.*)?$")
_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|mod|data|obj|exc|const):`~?([^`]+)`")


def _role(match: re.Match) -> str:
    target = match.group(1)
    if match.group(0).split("`")[1].startswith("~"):
        target = target.rsplit(".", 1)[-1]
    return f"`{target}`"


def _closing_paragraphs_as_notes(text: str) -> str:
    lines = text.split("\n")
    out: list[str] = []
    in_items = False
    for i, line in enumerate(lines):
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() and re.fullmatch(r"-{3,}", nxt.strip()):
            in_items = line.strip() in _SECTION_WITH_ITEMS
        elif (in_items and line and not line[0].isspace() and not re.fullmatch(r"-{3,}", line.strip())
              and i > 0 and not lines[i - 1].strip() and not _ITEM.match(line)):
            out += ["Notes", "-----"]
            in_items = False
        out.append(line)
    return "\n".join(out)


class HdidExports(griffe.Extension):
    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        if pkg.name != "hdid":
            return
        tree = ast.parse(pkg.filepath.read_text(encoding="utf-8"))
        lazy: dict[str, str] = {}
        for node in tree.body:
            if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets
            ):
                lazy = ast.literal_eval(node.value)
        for name, module in lazy.items():
            if name in pkg.members:
                continue
            target = "hdid" + module if module.startswith(".") else module
            if name != "effects":  # the module itself, not a member of it
                target = f"{target}.{name}"
            pkg.set_member(name, griffe.Alias(name, target, parent=pkg))

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is None:
            return
        text = _closing_paragraphs_as_notes(obj.docstring.value)
        obj.docstring.value = _ROLE.sub(_role, text) if ":`" in text else text
