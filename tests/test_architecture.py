"""docs/architecture.md's package map against the code: the import graph, computed from the sources
(every `import`, also those inside functions and under TYPE_CHECKING), has no cycle among the
modules of common/ and tools/ nor among their packages; every import between two packages of
common/ is one the table's "may import" column allows; the table's modules column and each
package's `__init__.py` list are the modules on disk; common/ imports neither apps/ nor tools/."""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "architecture.md"
COMMON = "nearsub.common"


def source_modules() -> dict[str, Path]:
    """Import name -> file, for every package pyproject.toml installs (its `package-dir`: the folder
    `common/` installs as `nearsub.common`)."""
    folders = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    modules = {}
    for package, folder in folders.items():
        for file in (ROOT / folder).glob("*.py"):
            modules[package if file.stem == "__init__" else f"{package}.{file.stem}"] = file
    return modules


def imported(name: str, file: Path, modules: dict[str, Path]) -> set[str]:
    """The modules of `modules` that module `name` imports (a package's `__init__` for a package)."""
    package = name if file.stem == "__init__" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(file.read_text(), str(file))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            names = [f"{base}.{alias.name}" for alias in node.names]
            targets = [n for n in names if n in modules]  # `from package import module`
            targets += [base] if len(targets) < len(names) else []
        else:
            continue
        for target in targets:
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph() -> dict[str, set[str]]:
    modules = source_modules()
    return {name: imported(name, file, modules) for name, file in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for other in graph.get(node, ()):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                other = stack.pop()
                component.append(other)
                if other == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def package_of(module: str) -> str:
    """`nearsub.common.physics.hull` -> `nearsub.common.physics`, `nearsub.tools.commands.log` ->
    `nearsub.tools.commands`; a module directly in tools/ is its own unit (`nearsub.tools.plot`)."""
    parts = module.split(".")
    return ".".join(parts[:3])


def package_map() -> dict[str, dict]:
    """The table of docs/architecture.md: package -> its modules and the packages it may import,
    in the table's order."""
    rows = {}
    for line in DOC.read_text().splitlines():
        match = re.match(r"\| `(\w+)/` \| [^|]+ \| ([^|]+) \| ([^|]+) \|$", line)
        if not match or match[3].strip() == "may import":  # the header
            continue
        name, modules, may = match.groups()
        listed = {item.strip().split()[0] for item in _top_level(modules)}
        if may.strip() == "nothing in common":
            allowed = set()
        elif may.strip() == "all of the above":
            allowed = set(rows)
        else:
            allowed = {item.strip().split()[0] for item in _top_level(may)}
        rows[name] = {"modules": {m for m in listed if not m.endswith("/")}, "may": allowed}
    return rows


def _top_level(text: str) -> list[str]:
    """`a, b (x, y), c` -> ['a', 'b (x, y)', 'c']: the commas outside parentheses split."""
    items, depth, current = [], 0, ""
    for char in text:
        depth += {"(": 1, ")": -1}.get(char, 0)
        if char == "," and depth == 0:
            items.append(current)
            current = ""
        else:
            current += char
    return items + [current]


GRAPH = import_graph()
MAP = package_map()


def test_the_doc_has_a_row_for_every_package_of_common():
    on_disk = {p.name for p in (ROOT / "common").iterdir() if (p / "__init__.py").exists()}
    assert set(MAP) == on_disk


@pytest.mark.parametrize("package", sorted(MAP))
def test_the_docs_modules_column_and_the_packages_list_are_the_modules_on_disk(package):
    on_disk = {f.stem for f in (ROOT / "common" / package).glob("*.py") if f.stem != "__init__"}
    assert MAP[package]["modules"] == on_disk, "docs/architecture.md's modules column"
    init = (ROOT / "common" / package / "__init__.py").read_text()
    assert set(re.findall(r"^- (\w+):", init, re.M)) == on_disk, f"common/{package}/__init__.py's list"


def test_no_import_cycle_among_the_modules_of_common_and_tools():
    ours = {m: {o for o in out if o.startswith(("nearsub.common.", "nearsub.tools."))} for m, out in GRAPH.items()}
    assert cycles({m: out for m, out in ours.items() if m.startswith(("nearsub.common.", "nearsub.tools."))}) == []


def test_no_import_cycle_among_the_packages_of_common_and_tools():
    packages: dict[str, set[str]] = {}
    for module, out in GRAPH.items():
        if module.startswith(("nearsub.common.", "nearsub.tools.")):
            mine = packages.setdefault(package_of(module), set())
            mine |= {package_of(o) for o in out if o.startswith(("nearsub.common.", "nearsub.tools."))}
    for package, out in packages.items():
        out.discard(package)
    assert cycles(packages) == []


def test_the_table_is_in_import_order():
    """Imports go up the table: what a package may import is all above it."""
    order = list(MAP)
    for package, row in MAP.items():
        assert row["may"] <= set(order[: order.index(package)]), package


def test_inside_tools_support_and_the_launcher_import_down_and_no_part_imports_a_command():
    """docs/architecture.md: `support/` imports nothing else of tools/, `launcher/` only `support/`,
    the modules of one subcommand (directly in tools/) nothing of `commands/`."""
    allowed = {"nearsub.tools.support": set(), "nearsub.tools.launcher": {"nearsub.tools.support"}}
    wrong = []
    for module, out in GRAPH.items():
        if not module.startswith("nearsub.tools.") or module == "nearsub.tools.cli":
            continue
        mine = package_of(module)
        for other in {package_of(o) for o in out if o.startswith("nearsub.tools.")} - {mine}:
            if mine in allowed and other not in allowed[mine]:
                wrong.append(f"{module} -> {other}")
            elif mine not in allowed and mine != "nearsub.tools.commands" and other == "nearsub.tools.commands":
                wrong.append(f"{module} -> {other}")
    assert wrong == []


def test_every_import_between_packages_of_common_is_one_the_doc_allows():
    forbidden = []
    for module, out in GRAPH.items():
        if not module.startswith(COMMON + "."):
            continue
        package = module.split(".")[2]
        for other in out:
            if other.startswith(("nearsub.apps", "nearsub.tools")):
                forbidden.append(f"{module} -> {other} (common/ never imports apps/ or tools/)")
            elif other.startswith(COMMON + ".") and (target := other.split(".")[2]) != package:
                if target not in MAP[package]["may"]:
                    forbidden.append(f"{module} -> {other}")
    assert forbidden == []
