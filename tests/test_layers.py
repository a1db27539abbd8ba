"""The package's layers point one way (issue 26): a test that walks every import, at module level
and inside functions, of every module of the installed package.

* models (and the spine: lagrangian, systems, signals, sensors, effects, simulate, data, reading) import no env, no
  training, no diagnosis, no command line; envs import neither training nor diagnosis;
* no module imports another subpackage's private module (``furuta_gym.envs._backends`` from
  ``furuta_gym.diagnose``): packages talk through their public ``__init__``.
"""

import ast
from pathlib import Path

import furuta_gym

ROOT = Path(furuta_gym.__file__).resolve().parent
REPO = ROOT.parent
# subpackage -> its folder (models/ and controllers/ are mapped into furuta_gym by package-dir)
FOLDERS = {"furuta_gym": ROOT, "furuta_gym.models": REPO / "models", "furuta_gym.controllers": REPO / "controllers"}
FORBIDDEN = {
    "models": {"envs", "training", "diagnose", "cli", "controllers", "demo"},
    "spine": {"envs", "training", "diagnose", "cli", "controllers", "demo"},
    "envs": {"training", "diagnose", "cli", "demo"},
    "controllers": {"training", "diagnose", "cli", "demo"},
    "training": {"diagnose", "cli", "demo"},
    "rl": {"training", "diagnose", "cli", "demo"},
    # the simulated rigs make logs to diagnose: they stand beside the diagnosis, not inside it
    "rigs": {"training", "diagnose", "cli", "demo"},
}
SPINE = {"lagrangian", "systems", "signals", "sensors", "effects", "simulate", "data", "reading"}


def _modules():
    seen = {}
    for package, folder in FOLDERS.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("")
            if package == "furuta_gym" and rel.parts[0] in ("models", "controllers"):
                continue
            parts = [p for p in rel.parts if p != "__init__"]
            seen[".".join([package, *parts])] = (path, path.name == "__init__.py")
    return seen


def _imports(name: str, path: Path, is_package: bool):
    """Absolute names of every module ``name`` imports (``from x import y``: x, and x.y)."""
    tree = ast.parse(path.read_text())
    base = name.split(".") if is_package else name.split(".")[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - node.level + 1]
                mod = ".".join(anchor + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append(mod)
            out += [f"{mod}.{a.name}" for a in node.names]
    return [m for m in out if m.startswith("furuta_gym")]


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if len(parts) < 2:
        return None
    top = parts[1]
    if top in SPINE or top.startswith("_"):
        return "spine" if top in SPINE else None
    return top


def _owner(module: str) -> str:
    """The subpackage a module belongs to (furuta_gym.envs._backends -> furuta_gym.envs)."""
    parts = module.split(".")
    return ".".join(parts[:2])


def test_layers_point_one_way_and_packages_talk_through_public_names():
    modules = _modules()
    problems = []
    for name, (path, is_package) in modules.items():
        layer = _layer(name)
        for target in _imports(name, path, is_package):
            target_layer = _layer(target)
            if target_layer in FORBIDDEN.get(layer, set()):
                problems.append(f"{name} imports {target} ({layer} must not depend on {target_layer})")
            private = any(p.startswith("_") and p != "__init__" for p in target.split(".")[2:3])
            if (
                private
                and _owner(target) != _owner(name)
                and target.split(".")[1] in {m.split(".")[1] for m in modules if m.count(".") >= 2}
            ):
                problems.append(f"{name} imports {target}, a private module of {_owner(target)}")
    assert not problems, "\n".join(sorted(set(problems)))


def test_the_walker_sees_function_level_and_relative_imports():
    # a relative import inside a function resolves to its absolute name
    found = _imports("furuta_gym.envs._backends", ROOT / "envs" / "_backends.py", False)
    assert "furuta_gym.models" in found or any(f.startswith("furuta_gym.models") for f in found)
    assert len(_modules()) > 50


def _name_branches(path: Path) -> list[int]:
    """Lines that compare something with a system's name (``== "furuta"``, ``!= "nmsd"``) or ask
    whether a system's name is in something (``"furuta" in systems``)."""
    from furuta_gym.systems import SYSTEMS

    def named(o):
        return isinstance(o, ast.Constant) and isinstance(o.value, str) and o.value in SYSTEMS

    lines = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Compare):
            continue
        equal = any(isinstance(op, (ast.Eq, ast.NotEq)) for op in node.ops)
        member = any(isinstance(op, (ast.In, ast.NotIn)) for op in node.ops)
        if (equal and any(named(o) for o in [node.left, *node.comparators])) or (member and named(node.left)):
            lines.append(node.lineno)
    return lines


def test_no_code_branches_on_a_system_name():
    # issue 26: what differs between systems lives in their definitions (models/_furuta.py,
    # models/_nmsd.py); a third system is one new module, not a new branch everywhere
    problems = [f"{path}:{line}" for path, _ in _modules().values() for line in _name_branches(path)]
    assert not problems, "branches on a system name:\n" + "\n".join(problems)


def test_the_branch_finder_sees_a_branch(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text(
        'def f(system, systems):\n    return 1 if system == "furuta" else "nmsd" != system\n'
        'def g(systems):\n    return "furuta" in systems, "nmsd" not in systems, "x" in systems\n'
    )
    assert _name_branches(sample) == [2, 2, 4, 4]


def _imported_modules(name: str, path: Path, is_package: bool, modules) -> set[str]:
    """The package's modules ``name`` imports, at module level or inside a function: ``import a.b``
    imports a.b; ``from x import y`` imports x.y when that is a module, else x. A module's own
    packages are left out: Python has started them before the module runs, so importing them
    cannot close a loop that the package's own imports did not."""
    base = name.split(".") if is_package else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            anchor = base[: len(base) - node.level + 1] if node.level else []
            mod = ".".join(anchor + ([node.module] if node.module else []))
            for alias in node.names:
                found.add(f"{mod}.{alias.name}" if f"{mod}.{alias.name}" in modules else mod)
    ancestors = {".".join(name.split(".")[:i]) for i in range(1, name.count(".") + 1)}
    return {m for m in found if m in modules and m != name and m not in ancestors}


def _import_graph() -> dict[str, set[str]]:
    """Each module of the package -> the package's modules it imports."""
    modules = _modules()
    return {name: _imported_modules(name, path, is_package, modules) for name, (path, is_package) in modules.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of ``graph``: one per strongly connected component of two or more
    modules (Tarjan), each named as a loop through the component."""
    index, low, stack, on_stack, components = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = _pop_component(stack, on_stack, node)
            if len(component) > 1:
                components.append(component)

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return [_loop_through(graph, set(c)) for c in components]


def _pop_component(stack: list[str], on_stack: set[str], root: str) -> list[str]:
    """Tarjan's step: the modules above and including ``root`` on the stack, one component."""
    component = []
    while True:
        member = stack.pop()
        on_stack.discard(member)
        component.append(member)
        if member == root:
            return component


def _loop_through(graph, component: set[str]) -> list[str]:
    """A closed path inside ``component`` starting at its first module (breadth-first back to it)."""
    start = min(component)
    parents, frontier = {start: None}, [start]
    while frontier:
        nxt_frontier = []
        for node in frontier:
            for nxt in sorted(graph[node] & component):
                if nxt == start:
                    path = [node]
                    while parents[path[-1]] is not None:
                        path.append(parents[path[-1]])
                    return [start, *reversed(path[:-1]), start] if node != start else [start, start]
                if nxt not in parents:
                    parents[nxt] = node
                    nxt_frontier.append(nxt)
        frontier = nxt_frontier
    return sorted(component)


def test_no_module_imports_itself_around_a_loop():
    # modules importing each other, directly or around a circle, at module level or in functions
    cycles = _cycles(_import_graph())
    assert not cycles, "import circles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_the_cycle_finder_names_a_loop():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e2"}, "e2": {"e"}}
    assert sorted(_cycles(graph)) == [["a", "b", "c", "a"], ["e", "e2", "e"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_env_base_class_stays_short():
    # LagrangianEnv holds the Gymnasium API and wiring; settings, observation, actuation, backends,
    # rendering and pickling live in their own modules, and a newcomer reads it in one sitting
    import inspect

    from furuta_gym.envs import LagrangianEnv

    lines, _ = inspect.getsourcelines(LagrangianEnv)
    assert len(lines) <= 300, f"LagrangianEnv is {len(lines)} lines; move a part into its own module"


def _top_module(node) -> str | None:
    """The top-level package a module-level import statement names first ("." for a relative
    one), None for any other statement."""
    if isinstance(node, ast.Import):
        return node.names[0].name.split(".")[0]
    if isinstance(node, ast.ImportFrom):
        return "." if node.level else (node.module or "").split(".")[0]
    return None


def test_scripts_import_furuta_gym_before_numpy():
    """A study or bench script that uses furuta_gym (anywhere: a function's import counts, as NumPy
    imported at the top has loaded all the same) imports it before any third-party module, itself
    or through a sibling script it imports first: NumPy loads its OpenBLAS on import, and only a
    BLAS loaded after furuta_gym gets its pinned core type and thread count, so a script that
    imports NumPy first computes other bits on other CPUs."""
    problems = []
    for folder in ("studies", "bench"):
        for path in sorted((REPO / folder).glob("*.py")):
            tree = ast.parse(path.read_text())
            anywhere = {r for r in map(_top_module, ast.walk(tree)) if r is not None}
            if "furuta_gym" in anywhere and path.name not in _OWN_NUMERICS:
                first = _first_third_party(path)
                if first not in (None, "furuta_gym"):
                    problems.append(f"{folder}/{path.name} imports {first} before furuta_gym")
    assert not problems, "\n".join(problems)


# the numerics studies set each process's environment themselves, pinned and not, before anything
# loads NumPy
_OWN_NUMERICS = {"cpu_numerics.py", "numerics_cost.py"}


def _first_third_party(path) -> str | None:
    """The first module a script's top-level imports load that is not the standard library's, a
    script of studies/ or bench/ (which put each other on the path) standing for what it loads
    first itself (None: nothing)."""
    import sys

    for root in map(_top_module, ast.parse(path.read_text()).body):
        if root is None or root in sys.stdlib_module_names | {"__future__"}:
            continue
        sibling = next(
            (d / f"{root}.py" for d in (REPO / "studies", REPO / "bench") if (d / f"{root}.py").exists()), None
        )
        if sibling is None:
            return root
        first = _first_third_party(sibling)
        if first is not None:
            return first
    return None


def test_scripts_use_only_public_names():
    """studies/ and bench/ are the package's first users: they import no private module and no
    private name of furuta_gym (a study that needs one shows a public API that is missing)."""
    problems = []
    for folder in ("studies", "bench"):
        for path in sorted((REPO / folder).glob("*.py")):
            for module in _imports(f"{folder}.{path.stem}", path, False):
                if any(part.startswith("_") for part in module.split(".")[1:]):
                    problems.append(f"{folder}/{path.name} imports {module}")
    assert not problems, "\n".join(problems)
    assert _imports("x.y", REPO / "tests" / "test_layers.py", False)  # the walker sees this file's imports
