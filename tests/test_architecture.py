"""The package's layout (issue 31, section 4): the import graph of sphcore, read from the source with ast
(imports at module level and inside functions), has no cycle; no function of a core module imports
another module of sphcore, except the few listed below with their reason (other packages may wait for
the function that uses them: pyvista, matplotlib and vulkan are optional or heavy, and load only
there); every error and warning class lives in sphcore/errors.py, and the old paths to them still work."""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "sphcore"
# the core: sphcore/*.py and these folders (validate/ is the validation cases, run from the CLI)
CORE = ("sph", "mc", "vk_runner", "solvers")
# (importer, imported) -> why the import waits for the function that needs it
LAZY = {
    ("sphcore.cli", "sphcore.runner"): "the CLI's start-up: numba loads only for `sphcore run`",
    ("sphcore.cli", "sphcore.parallel"): "the CLI's start-up: numba loads only for `sphcore run` (under mpiexec)",
    ("sphcore.cli", "sphcore.profile"): "the CLI's start-up: numba loads only for `sphcore run --profile`",
    ("sphcore.cli", "sphcore.plot"): "the CLI's start-up: numba loads only for `sphcore plot`",
    ("sphcore.cli", "sphcore.render"): "the CLI's start-up: numba and pyvista load only for `sphcore render`",
    ("sphcore.cli", "sphcore.validate.cli"): "the CLI's start-up: the validation commands are added last",
    ("sphcore.scene", "sphcore.sph.dfsph"): "a scene is read without numba (`sphcore keys`, the CLI's start-up); "
                                            "its neighbour lists' width is needed only where a run starts",
}


def module_name(path):
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in PACKAGE.rglob("*.py")}


def target(name):
    """The module of sphcore that importing `name` loads (the longest dotted prefix that is one), else None."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports(module):
    """[(imported module, inside a function)] of `module`, in source order."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                found.extend((target(a.name), inner) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    base = ".".join(package.split(".")[:len(package.split(".")) - child.level + 1] + ([base] if base else []))
                found.extend((target(f"{base}.{a.name}") if f"{base}.{a.name}" in MODULES else target(base), inner)
                             for a in child.names)
            visit(child, inner)

    visit(ast.parse(path.read_text(encoding="utf-8")), False)
    return [(name, inner) for name, inner in found if name is not None and name != module]


GRAPH = {module: imports(module) for module in MODULES}


def is_core(module):
    """sphcore/*.py and the modules of the CORE folders."""
    parts = module.split(".")[1:]
    return not parts or parts[0] in CORE or len(parts) == 1 and MODULES[module].name != "__init__.py"


def test_the_graph_is_read():
    """The reader sees what the package imports: a known module-level edge, a known lazy one and the sub-packages;
    and which modules are the core."""
    assert ("sphcore.stepper", False) in GRAPH["sphcore.runner"]
    assert ("sphcore.sph.dfsph", True) in GRAPH["sphcore.scene"]
    assert {"sphcore.sph.compute_density", "sphcore.vk_runner.context", "sphcore.validate.buchner",
            "sphcore.solvers.dfsph"} <= set(MODULES)
    assert all(map(is_core, ("sphcore", "sphcore.scene", "sphcore.sph.dfsph", "sphcore.vk_runner", "sphcore.solvers")))
    assert not any(map(is_core, ("sphcore.validate", "sphcore.validate.buchner")))


def test_no_import_cycle():
    """Depth-first search over every import (module level and inside functions): no module reaches itself."""
    state, stack = {}, []

    def walk(module):
        state[module] = "open"
        stack.append(module)
        for imported, _ in GRAPH[module]:
            if state.get(imported) == "open":
                cycle = stack[stack.index(imported):] + [imported]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if imported not in state:
                walk(imported)
        stack.pop()
        state[module] = "done"

    for module in sorted(GRAPH):
        if module not in state:
            walk(module)


def test_core_modules_import_at_module_level():
    """A function of a core module imports no module of sphcore, except those of LAZY (each with its reason);
    and every entry of LAZY is still needed."""
    lazy = {(module, imported) for module in GRAPH if is_core(module)
            for imported, inner in GRAPH[module] if inner}
    assert lazy - set(LAZY) == set(), "imports inside functions: " + ", ".join(f"{a} -> {b}" for a, b in sorted(lazy - set(LAZY)))
    assert set(LAZY) - lazy == set(), f"LAZY lists imports that are gone: {sorted(set(LAZY) - lazy)}"


def test_every_error_class_is_in_errors():
    """No module but sphcore/errors.py defines an exception or warning class (a class whose base's name ends
    in Error, Warning, Exception or Interrupt)."""
    elsewhere = []
    for module, path in MODULES.items():
        if module == "sphcore.errors":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef):
                bases = [b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases]
                if any(b.endswith(("Error", "Warning", "Exception", "Interrupt")) for b in bases):
                    elsewhere.append(f"{module}.{node.name}")
    assert not elsewhere, f"error classes outside sphcore/errors.py: {elsewhere}"


def test_old_paths_to_the_errors():
    import sphcore
    import sphcore.cache_trust
    import sphcore.checkpoint
    import sphcore.folder
    import sphcore.memory
    import sphcore.scene
    import sphcore.signals
    import sphcore.simulation
    import sphcore.validate.files
    import sphcore.vk_runner
    from sphcore import errors

    for old, name in ((sphcore, "SceneError"), (sphcore, "SimulationError"), (sphcore.scene, "SceneError"),
                      (sphcore.simulation, "SimulationError"), (sphcore.simulation, "CheckpointError"),
                      (sphcore.simulation, "Interrupted"), (sphcore.signals, "Interrupted"),
                      (sphcore.vk_runner, "VulkanError"), (sphcore.vk_runner, "ShaderCompileError"),
                      (sphcore.checkpoint, "CheckpointFieldError"), (sphcore.cache_trust, "CacheWarning"),
                      (sphcore.folder, "FolderError"), (sphcore.memory, "MemoryLimitError"),
                      (sphcore.validate.files, "ResultsError")):
        assert getattr(old, name) is getattr(errors, name), f"{old.__name__}.{name}"
    assert sphcore.run is sphcore.simulation.run and sphcore.Simulation is sphcore.simulation.Simulation


def test_every_package_is_installed():
    """Each folder of sphcore with an __init__.py is in pyproject.toml's packages (the wheel holds only those)."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    listed = set(tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    packages = {module for module, path in MODULES.items() if path.name == "__init__.py"}
    assert packages - listed == set()
