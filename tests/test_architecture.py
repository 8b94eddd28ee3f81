"""The rule of dependence (docs/ARCHITECTURE.md), read from the source's AST:

* firmware_ref imports nothing from host_tools, at module or function level;
* no import cycle between modules, imports inside functions counted (``PENDING_CYCLES``: cycles
  through modules other branches are changing, named until their merge);
* only the commands layer (host_tools/cli/) imports argparse;
* no module over ``MAX_LINES`` lines, except ``EXEMPT`` (deliberately unrolled kernels, whose
  module docstring says why) and ``PENDING_SIZE`` (modules being split on other branches).

An import edge goes to the module named: ``import a.b`` and ``from a.b import c`` -> ``a.b``, or
``a.b.c`` when ``c`` is a submodule; relative imports are resolved against the importing module.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("firmware_ref", "host_tools")
MAX_LINES = 700
# path -> reason; the reason must stand in the first lines of the module's docstring
EXEMPT: dict = {}
# Pending the merges of the branches that split or edit these modules; the integrator empties both
# sets (the tests below fail when an entry is no longer needed, so a stale one cannot stay).
PENDING_SIZE: set = set()
PENDING_CYCLES: set = set()     # frozensets of module names; none found on this branch


def modules() -> dict:
    """Dotted module name -> path, for every .py file of the packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


def imports(name: str, path: Path, known: dict, top_level_only: bool) -> list:
    """(line, imported module) for each import in the file; ``top_level_only``: skip the imports
    inside function bodies (module-level ``if``/``try`` blocks count)."""
    tree = ast.parse(path.read_text(), str(path))
    is_pkg = path.name == "__init__.py"
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import) and not (top_level_only and in_function):
                found.extend((child.lineno, a.name) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and not (top_level_only and in_function):
                base = child.module or ""
                if child.level:
                    here = name.split(".") if is_pkg else name.split(".")[:-1]
                    up = here[:len(here) - (child.level - 1)]
                    base = ".".join(up + ([base] if base else []))
                for a in child.names:
                    sub = f"{base}.{a.name}"
                    found.append((child.lineno, sub if sub in known else base))
            visit(child, inner)

    visit(tree, False)
    return found


def test_firmware_ref_imports_nothing_from_host_tools():
    known = modules()
    bad = [f"{path.relative_to(ROOT)}:{line}: imports {mod}"
           for name, path in known.items() if name.split(".")[0] == "firmware_ref"
           for line, mod in imports(name, path, known, top_level_only=False)
           if mod.split(".")[0] == "host_tools"]
    assert not bad, "firmware_ref must not depend on host_tools:\n" + "\n".join(bad)


def find_cycles(graph: dict) -> list:
    """The strongly connected components with more than one module (Tarjan), or a self-import."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def strong(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph.get(v, ()):
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def module_graph(top_level_only: bool = True) -> dict:
    """module -> the package modules it imports (``top_level_only`` False: imports inside functions
    count too)."""
    known = modules()
    return {name: sorted({mod for _, mod in imports(name, path, known, top_level_only) if mod in known})
            for name, path in known.items()}


def test_no_import_cycle_at_module_level():
    cycles = find_cycles(module_graph())
    assert not cycles, "import cycles at module level:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_import_cycle_counting_imports_inside_functions():
    """A function-level import is still a dependence: a cycle through one is a cycle."""
    cycles = {frozenset(c) for c in find_cycles(module_graph(top_level_only=False))}
    new = [sorted(c) for c in cycles - PENDING_CYCLES]
    stale = [sorted(c) for c in PENDING_CYCLES - cycles]
    assert not new, "import cycles (imports inside functions counted):\n" + "\n".join(" <-> ".join(c) for c in new)
    assert not stale, "PENDING_CYCLES entries that are no longer cycles (remove them): " + repr(stale)


def test_no_module_over_the_line_limit():
    sizes = {str(path.relative_to(ROOT)): len(path.read_text().splitlines()) for path in modules().values()}
    over = {p: n for p, n in sizes.items() if n > MAX_LINES}
    bad = sorted(set(over) - set(EXEMPT) - PENDING_SIZE)
    assert not bad, f"modules over {MAX_LINES} lines (split them along a real seam): " + \
        ", ".join(f"{p} ({over[p]})" for p in bad)
    stale = sorted(p for p in set(EXEMPT) | PENDING_SIZE if sizes.get(p, 0) <= MAX_LINES)
    assert not stale, f"EXEMPT/PENDING_SIZE entries no longer over {MAX_LINES} lines (remove them): {stale}"
    for path, reason in EXEMPT.items():
        doc = ast.get_docstring(ast.parse((ROOT / path).read_text())) or ""
        assert reason in "\n".join(doc.splitlines()[:5]), f"{path}: its docstring must say why at the top: {reason}"


def test_the_checks_can_fail():
    """The cycle finder and the import reader see what they must (so that a pass means something)."""
    assert find_cycles({"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}) == [["a", "b", "c"]]
    assert find_cycles({"a": ["b"], "b": []}) == []
    known = modules()
    found = [m for _, m in imports("host_tools.fixed.fixed_point", known["host_tools.fixed.fixed_point"], known, False)]
    assert "firmware_ref.compensate" in found and "host_tools.golden.runlog" in found
    assert "firmware_ref.formats" in module_graph()["firmware_ref.table"]
    # a function-level import is seen only when imports inside functions count
    assert "host_tools.fixed.fixed_point" in module_graph(top_level_only=False)["host_tools.golden.compensate"]
    assert "host_tools.fixed.fixed_point" not in module_graph()["host_tools.golden.compensate"]


def test_vocabulary_is_declared_once():
    """The golden model reads the vocabulary's tuples (not copies), and no argparse ``choices`` is a
    literal tuple/list repeating a vocabulary name."""
    from firmware_ref import vocabulary as VOC
    from host_tools.golden import compensate, flags, proxy, rate, regressors, reversal

    assert rate.ESTIMATORS is VOC.ESTIMATORS and proxy.KINDS is VOC.PROXY_KINDS
    assert reversal.COMBINERS is VOC.REVERSAL_COMBINERS and reversal.ORDERS is VOC.ORDERS
    assert regressors.AUX_GENERATORS is VOC.AUX_GENERATORS and compensate.FLAG_NAMES is VOC.GOLDEN_FLAG_NAMES
    assert flags.FLAG_NAMES == {bit: name for bit, (name, _) in VOC.FLAGS.items()}
    names = {n for v in vars(VOC).values() if isinstance(v, tuple) for n in v if isinstance(n, str)}
    bad = []
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.keyword) and node.arg == "choices" and isinstance(node.value, (ast.Tuple, ast.List)):
                lits = {e.value for e in node.value.elts if isinstance(e, ast.Constant)}
                if lits & names:
                    bad.append(f"{path.relative_to(ROOT)}:{node.value.lineno}: choices {sorted(lits)}")
    assert not bad, "argparse choices repeating the vocabulary (use firmware_ref.vocabulary):\n" + "\n".join(bad)


def test_only_the_commands_layer_imports_argparse():
    """Stage modules hold no argument parsing: argparse is imported (module or function level) only
    by host_tools/cli/ (the commands layer)."""
    known = modules()
    bad = [f"{path.relative_to(ROOT)}:{line}: imports argparse"
           for name, path in known.items() if not name.startswith("host_tools.cli")
           for line, mod in imports(name, path, known, top_level_only=False) if mod.split(".")[0] == "argparse"]
    assert not bad, "argparse outside host_tools/cli:\n" + "\n".join(bad)
    assert any(mod == "argparse" for _, mod in imports("host_tools.cli", known["host_tools.cli"], known, False))
