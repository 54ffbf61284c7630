"""The layout rules of docs/architecture.md, read from the source files with ``ast`` (nothing is imported):
the stage packages (``data_prep``, ``train``, ``infer``) never import one another, the library
(``mesh2tex``) imports no stage, no two modules import each other (directly or around a loop, at
module level or inside a function), the library raises no ``UserError`` (the command line's error:
the library's is ``InputError``, a ``ValueError``), no source file is longer than 500 lines
(nor a function than 80; those not yet split are listed at today's length), and a public
name is defined in one module (or says why it is shared). And the floors of docs/architecture.md: every
package of the library stands on a floor (:data:`FLOORS`), and no module imports a module of a higher
floor, so no two packages import each other."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = "mesh2tex"
STAGES = ("data_prep", "train", "infer", "evaluate", "app")
MAX_LINES = 500
USER_ERROR_MODULES = {"mesh2tex.cli", "mesh2tex.errors"}  # the command line's own error, and where it is defined


def module_files(root: Path = ROOT) -> dict[str, Path]:
    """{dotted module name: file} of the library and the stage packages, named as they are imported
    (a stage folder ``infer/`` of the source tree is the package ``mesh2tex.infer``)."""
    modules = {}
    for package in (LIBRARY, *STAGES):
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if package != LIBRARY:
                parts = [LIBRARY, *parts]
            modules[".".join(parts)] = path
    return modules


def imported_modules(name: str, path: Path, known: set[str]) -> set[str]:
    """The modules of ``known`` that module ``name`` (at ``path``) imports anywhere in its body.

    ``from a.b import c`` counts as importing ``a.b.c`` when that is a module, else ``a.b``;
    relative imports are resolved against the module's package."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in known:  # 'import a.b.c' of a package path: its closest known module
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    files = module_files(root)
    known = set(files)
    return {name: imported_modules(name, path, known) for name, path in files.items()}


def top(name: str) -> str:
    """The package ``name`` belongs to: a stage (``mesh2tex.infer.demo`` -> ``infer``) or the library."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == LIBRARY and parts[1] in STAGES else parts[0]


def cross_package_imports(graph: dict[str, set[str]]) -> list[str]:
    """'a -> b' for every import of a stage by another stage or by the library."""
    bad = []
    for name, targets in sorted(graph.items()):
        for target in sorted(targets):
            if top(target) in STAGES and top(target) != top(name):
                bad.append(f"{name} -> {target}")
    return bad


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph.get(node, ()):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return cycles


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_the_graph_sees_the_imports(graph):
    """A guard for the checks below: the walker finds imports of every form the code uses."""
    assert "mesh2tex.render.cameras" in graph["mesh2tex.render"]  # relative, from a package's __init__
    assert "mesh2tex.runtime" in graph["mesh2tex.infer.generate"]  # from a module import a name
    assert "mesh2tex.transfer" in graph["mesh2tex.evaluation.protocols"]  # from a package import a submodule
    assert all(top(t) in (LIBRARY, *STAGES) for targets in graph.values() for t in targets)


def test_no_stage_imports_another_stage_and_the_library_imports_none(graph):
    assert cross_package_imports(graph) == [], "stages share code through the library (docs/architecture.md)"


def test_no_import_cycles(graph):
    assert import_cycles(graph) == []


def test_the_checks_find_what_they_forbid():
    graph = {
        "mesh2tex.infer.a": {"mesh2tex.train.b", "mesh2tex.c"},
        "mesh2tex.train.b": set(),
        "mesh2tex.c": {"mesh2tex.infer.a"},
        "mesh2tex.d": {"mesh2tex.e"},
        "mesh2tex.e": {"mesh2tex.f"},
        "mesh2tex.f": {"mesh2tex.d"},
    }
    assert cross_package_imports(graph) == ["mesh2tex.c -> mesh2tex.infer.a", "mesh2tex.infer.a -> mesh2tex.train.b"]
    assert import_cycles(graph) == [["mesh2tex.c", "mesh2tex.infer.a"], ["mesh2tex.d", "mesh2tex.e", "mesh2tex.f"]]


# The floors of docs/architecture.md, lowest first: a package (a folder or a module directly under mesh2tex/,
# or a stage) imports its own floor and the floors below, never one above.
FLOORS = [
    ("foundation", {"mesh2tex", "errors", "limits", "checks"}),
    ("files and settings", {"io", "config", "progress", "runtime"}),
    ("geometry", {"geometry"}),
    ("rendering", {"render"}),
    ("content", {"nn", "photos", "synthetic"}),
    ("measures and objectives", {"metrics", "losses"}),
    ("trained models", {"models", "texturing"}),
    ("methods", {"transfer", "evaluation", "texel_synthesis"}),
    ("commands", {"options", "cli", "__main__", *STAGES}),
]


def package(name: str) -> str:
    """The floor unit of a module: ``mesh2tex.render.uv`` -> ``render``, ``mesh2tex.infer.demo`` -> ``infer``,
    ``mesh2tex`` (the package's own ``__init__``) -> ``mesh2tex``."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def floor_of(unit: str) -> int:
    for level, (_, units) in enumerate(FLOORS):
        if unit in units:
            return level
    raise KeyError(unit)


def floor_violations(graph: dict[str, set[str]]) -> list[str]:
    """'a -> b (floor x -> floor y)' for every import of a module on a higher floor than the importer's."""
    bad = []
    for name, targets in sorted(graph.items()):
        for target in sorted(targets):
            here, there = floor_of(package(name)), floor_of(package(target))
            if there > here:
                bad.append(f"{name} -> {target} ({FLOORS[here][0]} -> {FLOORS[there][0]})")
    return bad


def package_loops(graph: dict[str, set[str]]) -> list[list[str]]:
    """The loops between packages (folder level): strongly connected components of the package graph."""
    packages: dict[str, set[str]] = {}
    for name, targets in graph.items():
        packages.setdefault(package(name), set()).update(package(t) for t in targets if package(t) != package(name))
    return import_cycles(packages)


def test_every_package_stands_on_a_floor(graph):
    unplaced = sorted({package(name) for name in graph} - set().union(*(units for _, units in FLOORS)))
    assert unplaced == [], "add each new package to FLOORS (and to the floors of docs/architecture.md)"


def test_no_module_imports_a_higher_floor(graph):
    assert floor_violations(graph) == [], (
        "an import climbs a floor: move the shared piece down (docs/architecture.md, 'Floors')"
    )


def test_no_two_packages_import_each_other(graph):
    assert package_loops(graph) == []


def test_the_floors_in_the_docs_are_the_floors_checked():
    """docs/architecture.md lists the floors, top first, one line each: `n. name: unit, unit`."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    listed = []
    for line in text.split("## Floors", 1)[1].split("\n## ", 1)[0].splitlines():
        head, _, units = line.partition(":")
        if head[:1].isdigit() and ". " in head:
            listed.append(
                (head.split(". ", 1)[1].strip(), {u.strip(" `") for u in units.split("(")[0].split(",") if u.strip()})
            )
    assert listed[::-1] == FLOORS


def test_the_floor_checks_find_what_they_forbid():
    graph = {"mesh2tex.render.a": {"mesh2tex.nn.b"}, "mesh2tex.nn.b": {"mesh2tex.render.c"}, "mesh2tex.render.c": set()}
    assert floor_violations(graph) == ["mesh2tex.render.a -> mesh2tex.nn.b (rendering -> content)"]
    assert package_loops(graph) == [["nn", "render"]]


def user_error_lines(source: str) -> list[int]:
    """The lines of ``source`` that import, raise or otherwise name ``UserError``."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.Name):
            names = [node.id]
        elif isinstance(node, ast.Attribute):  # errors.UserError
            names = [node.attr]
        else:
            continue
        if "UserError" in names:
            lines.append(node.lineno)
    return sorted(lines)


def test_the_library_raises_no_user_error():
    """A program calling the library catches its bad-input errors as ValueError; turning them into the
    one-line ``mesh2tex: error:`` is the command line's job (mesh2tex/cli.py)."""
    uses = [
        f"{path.relative_to(ROOT)}:{line}"
        for name, path in module_files().items()
        if top(name) == LIBRARY and name not in USER_ERROR_MODULES
        for line in user_error_lines(path.read_text())
    ]
    assert uses == [], "the library raises InputError (mesh2tex/errors.py)"


def test_the_user_error_check_finds_what_it_forbids():
    source = (
        "from mesh2tex.errors import InputError, UserError\nimport mesh2tex.errors as e\n\n"
        "def f():\n    raise e.UserError('x')\n\ndef g():\n    raise InputError('y')\n"
    )
    assert user_error_lines(source) == [1, 5]


# Files over MAX_LINES and functions over MAX_FUNCTION_LINES not yet split, each at its length today: it may
# shrink, not grow, and leaves the list once it fits (the target is an empty list).
LONG_FILES: dict[str, int] = {}
MAX_FUNCTION_LINES = 80
LONG_FUNCTIONS: dict[str, int] = {}
SOURCE_FOLDERS = (LIBRARY, *STAGES)


def long_files(folders=(LIBRARY, *STAGES, "tests", "benchmarks", "models")) -> dict[str, int]:
    return {
        str(p.relative_to(ROOT)): n
        for folder in folders
        for p in sorted((ROOT / folder).rglob("*.py"))
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    }


def long_functions(source: str) -> dict[str, int]:
    """{name: lines} of the functions and methods of ``source`` longer than MAX_FUNCTION_LINES."""
    return {
        node.name: node.end_lineno - node.lineno + 1
        for node in ast.walk(ast.parse(source))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    }


def test_no_source_file_is_longer_than_500_lines():
    found = long_files()
    grown = {f: n for f, n in found.items() if n > LONG_FILES.get(f, MAX_LINES)}
    assert grown == {}, "split a long file by job"
    assert sorted(set(LONG_FILES) - set(found)) == [], "a listed file fits now: drop it from LONG_FILES"


def test_no_function_is_longer_than_80_lines():
    found = {
        f"{p.relative_to(ROOT)}:{name}": n
        for folder in SOURCE_FOLDERS
        for p in sorted((ROOT / folder).rglob("*.py"))
        for name, n in long_functions(p.read_text()).items()
    }
    grown = {f: n for f, n in found.items() if n > LONG_FUNCTIONS.get(f, MAX_FUNCTION_LINES)}
    assert grown == {}, "split a long function into named steps"
    assert sorted(set(LONG_FUNCTIONS) - set(found)) == [], "a listed function fits now: drop it from LONG_FUNCTIONS"


# One spelling in identifiers: the project writes British "colour" and "centre". The names below are kept
# because the project does not own them; each is where its definition is, with why.
SPELLING_FOLDERS = (LIBRARY, *STAGES, "tests", "benchmarks", "models")
AMERICAN = ("color", "center")
KEPT_SPELLINGS = {
    # Pattern dataclass fields: describe() writes them as keys of each world's ground-truth material JSON
    ("mesh2tex/synthetic/materials.py", "color"): "persisted key",
    ("mesh2tex/synthetic/materials.py", "color_a"): "persisted key",
    ("mesh2tex/synthetic/materials.py", "color_b"): "persisted key",
    # Blender's Python API (scene.render.image_settings.color_mode), set in the Blender-side script
    ("benchmarks/blender_scene.py", "color_mode"): "external name",
}


def defined_names(source: str) -> list[tuple[int, str]]:
    """(line, name) of every name ``source`` defines: functions, classes, arguments, assigned names and
    attributes (``x = ``, ``self.x = ``, loop, ``with`` and comprehension targets, class fields), import
    aliases and exception names. Names only used (a library's attribute read, a keyword argument) are not."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            found.append((node.lineno, node.name))
        elif isinstance(node, ast.arg):
            found.append((node.lineno, node.arg))
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            found.append((node.lineno, node.id))
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            found.append((node.lineno, node.attr))
        elif isinstance(node, ast.alias) and node.asname:
            found.append((node.lineno, node.asname))
        elif isinstance(node, ast.ExceptHandler) and node.name:
            found.append((node.lineno, node.name))
    return sorted(found)


def american_spellings(source: str) -> list[tuple[int, str]]:
    return [(line, name) for line, name in defined_names(source) if any(word in name.lower() for word in AMERICAN)]


def test_identifiers_spell_colour_and_centre():
    found = {
        (str(p.relative_to(ROOT)), name): line
        for folder in SPELLING_FOLDERS
        for p in sorted((ROOT / folder).rglob("*.py"))
        for line, name in american_spellings(p.read_text())
    }
    assert (
        sorted(f"{path}:{line}: {name}" for (path, name), line in found.items() if (path, name) not in KEPT_SPELLINGS)
        == []
    ), "spell project identifiers 'colour' and 'centre' (or add an external or persisted name to KEPT_SPELLINGS)"
    assert sorted(set(KEPT_SPELLINGS) - set(found)) == [], "a kept name is gone: drop it from KEPT_SPELLINGS"


def test_the_spelling_check_finds_what_it_forbids():
    source = (
        "import numpy as colorful\n\nclass Colors:\n    color_a: int\n\n    def centers(self, center, *colors):\n"
        "        self.colour = 1\n        self.centerline = [c for c in center]\n        for tint_color in colors:\n"
        "            pass\n        return image.vertex_colors, f(color=1)\n"
    )
    assert american_spellings(source) == [
        (1, "colorful"),
        (3, "Colors"),
        (4, "color_a"),
        (6, "center"),
        (6, "centers"),
        (6, "colors"),
        (8, "centerline"),
        (9, "tint_color"),
    ]


# Public names defined at module level in more than one module, each for a stated reason; any other repeat is a name
# with two meanings (or one job written twice).
SHARED_NAMES = {
    "run": "every command's entry point (docs/architecture.md, 'a command')",
    "build_config": "every configured command's config, for --print-config",
    "output_names": "the files each of infer transfer and infer generate writes into --out",
    "nca": "the options of 'train nca' and 'infer nca', each in its package's options.py",
    "random_cameras": "each trainer's own distribution of training views (the GAN's jittered, the automaton's seeded)",
    "quad_normals": "the prepared features' float64 NumPy form (geometry.features) and the renderer's torch form",
    "vertex_normals": "the same: quads in NumPy for the prepared features, triangles in torch for shading",
}


def public_definitions(root: Path = ROOT) -> dict[str, list[str]]:
    """{name: [module, ...]} of the public classes and functions defined at module level."""
    found: dict[str, list[str]] = {}
    for module, path in module_files(root).items():
        for node in ast.parse(path.read_text(), str(path)).body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and not node.name.startswith(
                "_"
            ):
                found.setdefault(node.name, []).append(module)
    return found


def test_a_public_name_means_one_thing():
    repeated = {name: modules for name, modules in public_definitions().items() if len(modules) > 1}
    assert sorted(set(repeated) - set(SHARED_NAMES)) == [], (
        f"defined in more than one module: { ({n: m for n, m in repeated.items() if n not in SHARED_NAMES}) }; rename "
        "one, or say why in SHARED_NAMES"
    )
    assert sorted(set(SHARED_NAMES) - set(repeated)) == [], (
        "a shared name is defined once now: drop it from SHARED_NAMES"
    )


def test_the_name_check_finds_what_it_forbids(tmp_path):
    for package in (LIBRARY, *STAGES):
        (tmp_path / package).mkdir()
    (tmp_path / LIBRARY / "a.py").write_text("class View:\n    pass\n\ndef _helper():\n    pass\n")
    (tmp_path / "infer" / "b.py").write_text("def View():\n    pass\n\ndef _helper():\n    pass\n")
    assert public_definitions(tmp_path) == {"View": [f"{LIBRARY}.a", "mesh2tex.infer.b"]}
