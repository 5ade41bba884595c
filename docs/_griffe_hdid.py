"""Griffe extension for hdid's API pages (loaded by mkdocs.yml).

1. ``hdid/__init__.py`` exports its public names lazily (a ``_LAZY`` table of
   name → module read by ``__getattr__``). Static analysis sees only the names also
   imported under ``TYPE_CHECKING``; this adds every ``_LAZY`` name as an alias of its
   module's object, so ``::: hdid.NAME`` works for every export and a new export needs
   no edit here.
2. hdid's docstrings use Sphinx roles (``:func:`hdid.read_log```); Markdown shows those
   as plain code (``hdid.read_log``; a ``~`` keeps the last part only).
"""

from __future__ import annotations

import ast
import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|mod|data|obj|exc|const):`~?([^`]+)`")


def _role(match: re.Match) -> str:
    target = match.group(1)
    if match.group(0).split("`")[1].startswith("~"):
        target = target.rsplit(".", 1)[-1]
    return f"`{target}`"


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
        if obj.docstring is not None and ":`" in obj.docstring.value:
            obj.docstring.value = _ROLE.sub(_role, obj.docstring.value)
