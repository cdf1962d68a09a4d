"""The package's layout, read from its imports: no cycle, and each wing imports only what it may.

Every ``import`` and ``from … import`` of a ``pbf`` module counts, at module level or inside a
function, so an import hidden in a function cannot break a rule unseen.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "pbf"
PLOTTING_AND_APPLICATION = ("matplotlib", "argparse", "imageio", "tqdm", "PIL", "plyfile")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports(name: str) -> set[str]:
    """Every module ``name`` imports (pbf modules resolved to the module, not the package, where a
    ``from pbf.x import y`` names a submodule), and the top-level names of outside libraries."""
    found = set()
    for node in ast.walk(ast.parse(MODULES[name].read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            for alias in node.names:
                candidate = f"{node.module}.{alias.name}"
                found.add(candidate if candidate in MODULES else node.module)
    return found


GRAPH = {name: {m for m in imports(name) if m in MODULES} for name in MODULES}


def wing(name: str) -> str:
    return name.split(".")[1] if name.count(".") >= 1 else "face"


def test_every_module_is_seen():
    assert {"pbf.scene", "pbf.scene.root", "pbf.solver.simulation", "pbf.app.cli", "pbf.study.sweep"} <= set(MODULES)


def test_no_import_cycle():
    # A package's __init__ re-exports its modules; Python imports the package before a submodule, so
    # an edge from a submodule back to its own package is no cycle. Every other edge counts.
    def edges(name):
        return {m for m in GRAPH[name] if not (name.startswith(m + ".") and MODULES[m].name == "__init__.py")}

    state = {}

    def visit(name, path):
        state[name] = "open"
        for target in sorted(edges(name)):
            if state.get(target) == "open":
                pytest.fail("import cycle: " + " → ".join(path[path.index(target) :] + [target]))
            if target not in state:
                visit(target, path + [target])
        state[name] = "done"

    for name in MODULES:
        if name not in state:
            visit(name, [name])


@pytest.mark.parametrize("name", [n for n in MODULES if wing(n) == "solver"])
def test_solver_imports_only_the_schema_and_itself(name):
    outside = {m for m in GRAPH[name] if wing(m) not in ("solver", "scene")}
    assert not outside, f"{name} imports {sorted(outside)}"
    libraries = {m.split(".")[0] for m in imports(name)} & set(PLOTTING_AND_APPLICATION)
    assert not libraries, f"{name} imports {sorted(libraries)}"


@pytest.mark.parametrize("name", [n for n in MODULES if wing(n) == "scene"])
def test_scene_schema_imports_no_wing(name):
    outside = {m for m in GRAPH[name] if m != "pbf" and wing(m) != "scene"}
    assert not outside, f"{name} imports {sorted(outside)}"


@pytest.mark.parametrize("name", [n for n in MODULES if wing(n) == "app"])
def test_app_uses_the_solver_face_only(name):
    inner = {m for m in GRAPH[name] if wing(m) == "solver" and m != "pbf.solver"}
    assert not inner, f"{name} reaches into {sorted(inner)}; use pbf.solver's public face"
    assert not {m for m in GRAPH[name] if wing(m) == "study"}, f"{name} imports the study wing"


def test_the_product_imports_nothing_of_the_lab():
    # benchmarks/ is the lab, run from a checkout; the wheel ships pbf alone.
    lab = {name: sorted(m for m in imports(name) if m.split(".")[0] == "benchmarks") for name in MODULES}
    assert not {name: found for name, found in lab.items() if found}


def test_the_study_wing_holds_what_a_user_runs_to_report_and_validate():
    # The sweep, the validations and the headline table, with their helpers; the rest is the lab's.
    study = {name.removeprefix("pbf.study.") for name in MODULES if wing(name) == "study" and name != "pbf.study"}
    assert study == {"common", "damping", "headline", "spheric", "sweep", "validate"}
