"""The import contract: each layer imports only from the layers below it, and no module cycle.

The order (documented in ``docs/architecture.md``), lowest first::

    _check, _files, _dask, _malloc → layout → viz → electrostatics → io → twin → learn → report → pipeline
      → design → live → dashboard → commands → cli

``viz`` sits low on purpose: plot functions take arrays (and the layout, to draw the faces) and
return figures, so every layer above can own its figures. Function-local imports count the same
as top-level ones: an import hidden inside a function still couples the two modules.

Beside the contract, a ceiling on file sizes (:func:`size_problems`): no source file over
``MAX_LINES`` lines and at most ``MAX_LARGE_FILES`` over ``LARGE_LINES``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import ectskin

SRC = Path(ectskin.__file__).resolve().parent

LAYERS = (
    ("_check", "_files", "_dask", "_malloc", "__init__"),
    ("layout",),
    ("viz",),
    ("electrostatics",),
    ("io",),
    ("twin",),
    ("inversion",),
    ("learn",),
    ("report",),
    ("pipeline",),
    ("design",),
    ("study",),
    ("live",),
    ("dashboard",),
    ("commands",),
    ("cli", "__main__"),
)
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}


def _module_name(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path, module: str) -> set[str]:
    """Every ``ectskin.*`` module that ``path`` imports, at any depth in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "ectskin"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "ectskin":
                continue
            found.add(target)
            for a in node.names:  # `from ectskin.learn import train` imports a module
                if (SRC.parent / (target.replace(".", "/") + f"/{a.name}.py")).exists() or (
                    SRC.parent / (target.replace(".", "/") + f"/{a.name}/__init__.py")
                ).exists():
                    found.add(f"{target}.{a.name}")
    found.discard(module)
    return found


def _graph() -> dict[str, set[str]]:
    graph = {}
    for path in sorted(SRC.rglob("*.py")):
        mod = _module_name(path)
        graph[mod] = _imports(path, mod)
    return graph


def _layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_every_package_has_a_layer():
    unknown = sorted({_layer(m) for m in _graph()} - set(RANK))
    assert not unknown, f"add these packages to LAYERS (and docs/architecture.md): {unknown}"


def test_no_layer_imports_a_higher_one():
    bad = []
    for mod, deps in _graph().items():
        for dep in deps:
            if dep == "ectskin":
                continue  # the package root: __version__ and EctskinError
            if RANK[_layer(dep)] > RANK[_layer(mod)]:
                bad.append(f"{mod} imports {dep}")
    assert not bad, "layer order violated:\n" + "\n".join(sorted(bad))


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
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
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    graph = {m: {d for d in deps if d != "ectskin"} for m, deps in _graph().items()}
    cycles = _cycles(graph)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_the_contract_catches_a_violation():
    """The checker itself: an upward import and a two-module cycle are both found."""
    graph = {"ectskin.layout.x": {"ectskin.learn.y"}, "ectskin.learn.y": {"ectskin.layout.x"}}
    assert _cycles(graph) == [["ectskin.layout.x", "ectskin.learn.y"]]
    assert RANK[_layer("ectskin.learn.y")] > RANK[_layer("ectskin.layout.x")]


# ---------------------------------------------------------------------------- file sizes
#: no source file has more lines than this
MAX_LINES = 700
#: a file over this many lines is large, and at most MAX_LARGE_FILES files are
LARGE_LINES = 600
MAX_LARGE_FILES = 2


def _line_counts(root: Path) -> dict[str, int]:
    """Lines of every ``.py`` file under ``root``, by path relative to it."""
    return {
        str(p.relative_to(root)): p.read_text(encoding="utf-8").count("\n")
        for p in sorted(root.rglob("*.py"))
    }


def size_problems(root: Path) -> list[str]:
    """What breaks the size rule under ``root``: a file over :data:`MAX_LINES` lines, or more
    than :data:`MAX_LARGE_FILES` files over :data:`LARGE_LINES`. Nothing in a file exempts it."""
    counts = _line_counts(root)
    problems = [
        f"{name} has {n} lines (at most {MAX_LINES})" for name, n in counts.items() if n > MAX_LINES
    ]
    large = [f"{name} ({n})" for name, n in counts.items() if n > LARGE_LINES]
    if len(large) > MAX_LARGE_FILES:
        problems.append(
            f"{len(large)} files over {LARGE_LINES} lines (at most {MAX_LARGE_FILES}): "
            + ", ".join(large)
        )
    return problems


def test_source_files_stay_small():
    """Split a file that grows past the ceiling by job (as twin/simulate.py was: response models,
    trials, the process pool)."""
    problems = size_problems(SRC)
    assert not problems, "source files too large:\n" + "\n".join(problems)


def _write_lines(path: Path, n: int, doc: str = "") -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    head = f'"""{doc}"""\n' if doc else ""
    path.write_text(head + "x = 0\n" * (n - head.count("\n")), encoding="utf-8")


def test_the_size_rule_catches_a_file_over_the_ceiling(tmp_path):
    _write_lines(tmp_path / "pkg" / "a.py", MAX_LINES)
    _write_lines(tmp_path / "b.py", 10)
    assert _line_counts(tmp_path) == {"b.py": 10, "pkg/a.py": MAX_LINES}
    assert size_problems(tmp_path) == []
    # one line more, with the old escape word in its docstring: still refused
    _write_lines(tmp_path / "pkg" / "a.py", MAX_LINES + 1, doc="Size: one class, read together.")
    assert size_problems(tmp_path) == [f"pkg/a.py has {MAX_LINES + 1} lines (at most {MAX_LINES})"]


def test_the_size_rule_allows_only_a_few_large_files(tmp_path):
    for name in ("a.py", "b.py"):
        _write_lines(tmp_path / name, LARGE_LINES + 1)
    _write_lines(tmp_path / "c.py", LARGE_LINES)
    assert size_problems(tmp_path) == []
    _write_lines(tmp_path / "sub" / "c.py", LARGE_LINES + 50)
    assert size_problems(tmp_path) == [
        f"3 files over {LARGE_LINES} lines (at most {MAX_LARGE_FILES}): a.py ({LARGE_LINES + 1}), "
        f"b.py ({LARGE_LINES + 1}), sub/c.py ({LARGE_LINES + 50})"
    ]
