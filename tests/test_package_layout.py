"""The package's layout is the pipeline's: no import cycle, lower layers never
import higher ones, nobody imports another component's private names, and
the README's layout section names every sub-package and module.

Imports are read from the source (every ``import`` and ``from ... import``,
at module level or inside functions), not executed.
"""

import ast
import re

from conftest import ROOT

PACKAGE = ROOT / "oclgi"

# What each layer may not import (prefixes of module names).
FORBIDDEN = {
    "oclgi.cl": ("oclgi.scene", "oclgi.accel", "oclgi.tracing", "oclgi.estimators", "oclgi.incremental",
                 "oclgi.study", "oclgi.engine", "oclgi.params", "oclgi.queries", "oclgi.io"),
    "oclgi.scene": ("oclgi.estimators", "oclgi.tracing", "oclgi.incremental", "oclgi.study", "oclgi.engine"),
    "oclgi.accel": ("oclgi.estimators", "oclgi.tracing", "oclgi.incremental", "oclgi.study", "oclgi.engine"),
    "oclgi.tracing": ("oclgi.estimators", "oclgi.incremental", "oclgi.study", "oclgi.engine"),
    "oclgi.estimators": ("oclgi.tracing", "oclgi.incremental", "oclgi.study", "oclgi.engine"),
    "oclgi.incremental": ("oclgi.study",),
    "oclgi.params": ("oclgi.",),
    "oclgi.errors": ("oclgi.",),
}
ALLOWED = {"oclgi.params": ("oclgi.errors",)}


def _modules():
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name, path):
    """(imported module, imported name or None) pairs of module ``name``."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("oclgi"):
                continue
            for alias in node.names:
                full = f"{target}.{alias.name}"
                out.append((full, None) if full in MODULES else (target, alias.name))
        elif isinstance(node, ast.Import):
            out.extend((a.name, None) for a in node.names if a.name.startswith("oclgi"))
    return out


GRAPH = {name: {m for m, _ in _imports(name, path)} for name, path in MODULES.items()}


def test_the_import_graph_was_read():
    assert len(MODULES) > 40 and "oclgi.accel.bvh_build" in GRAPH["oclgi.scene.compiled"]
    assert "oclgi.incremental.segment_store" in GRAPH["oclgi.incremental.session"]


def test_no_import_cycle():
    def reachable(start):
        seen, todo = set(), [start]
        while todo:
            for nxt in GRAPH.get(todo.pop(), ()):
                # a module importing its own package's __init__ is not a cycle
                if nxt not in seen and not start.startswith(nxt + "."):
                    seen.add(nxt)
                    todo.append(nxt)
        return seen

    cycles = [m for m in MODULES if m in reachable(m)]
    assert not cycles, f"modules on an import cycle: {sorted(cycles)}"


def test_lower_layers_do_not_import_higher_ones():
    bad = []
    for name, targets in GRAPH.items():
        for layer, forbidden in FORBIDDEN.items():
            if name == layer or name.startswith(layer + "."):
                for t in targets:
                    if t.startswith(forbidden) and not t.startswith(ALLOWED.get(layer, ("\0",))) \
                            and not t.startswith(layer):
                        bad.append(f"{name} imports {t}")
    assert not bad, "\n".join(bad)


def test_no_private_name_is_imported_across_components():
    def component(mod):
        return ".".join(mod.split(".")[:2])

    bad = [f"{name} imports {target}.{attr}" for name, path in MODULES.items()
           for target, attr in _imports(name, path)
           if attr and attr.startswith("_") and not (attr.startswith("__") and attr.endswith("__"))
           and component(target) != component(name)]  # dunders (__version__) are public
    assert not bad, "\n".join(bad)


def test_readme_layout_names_every_package_and_module():
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Layout"):]
    section = section[:section.index("\n## ", 1)]
    missing = []
    for name, path in MODULES.items():
        if path.name == "__init__.py":
            if name != "oclgi" and f"{path.parent.name}/" not in section:
                missing.append(f"{path.parent.name}/")
        elif path.stem not in ("__main__", "errors", "progress") and not re.search(rf"\b{path.stem}(\.py)?\b", section):
            missing.append(str(path.relative_to(ROOT)))
    assert not missing, f"README's layout section does not name: {missing}"
