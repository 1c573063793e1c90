"""The layer order inside ``app/``, ``annotate/``, ``bench/``, ``model/`` and ``scenes/``
(docs/DESIGN.md's ``layers`` blocks) and between every top-level package (its ``packages``
block) holds.

docs/DESIGN.md is the one home of the order: its fenced ``layers`` blocks list units (a package,
sub-package or module; a unit holds its sub-modules, the most specific unit wins; a package's own
``__init__`` is its root unit and holds nothing else) one line per layer, top layer first. A module
may import its own unit and any unit on a line below its own; units on one line are peers and
import neither each other nor anything above. Every import statement counts: ``import x`` and
``from x import y`` at module level, in functions and under ``if TYPE_CHECKING:`` (a type-only
import is still an arrow a reader follows, and ``../shared/tools/arch_check.py`` counts it for
cycles too), and ``importlib.import_module("...")`` with a literal name.
"""

from __future__ import annotations

import ast
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.paths import REPO as ROOT

DESIGN = ROOT / "docs" / "DESIGN.md"
PACKAGES = ("annotate", "app", "bench", "model", "scenes")
MAX_MODULES_PER_FOLDER = 20


@dataclass(frozen=True)
class Layers:
    """The units of one package and the layer of each (0 = the bottom)."""

    level: dict[str, int]
    """Unit -> its line, counted from the bottom."""
    line: dict[str, int]
    """Unit -> its line number in docs/DESIGN.md (for messages)."""


def read_layers(text: str, where: str = "docs/DESIGN.md") -> dict[str, Layers]:
    """The ``layers`` blocks of a markdown text, per top-level package.

    Raises:
        ValueError: a unit named twice, or a block mixing packages (names the line).
    """
    out: dict[str, Layers] = {}
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].strip() != "```layers":
            i += 1
            continue
        rows: list[tuple[int, list[str]]] = []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            content = lines[i].split("#", 1)[0].split()
            if content:
                rows.append((i + 1, content))
            i += 1
        if not rows:
            raise ValueError(f"{where}: an empty layers block before line {i + 1}")
        package = rows[0][1][0].split(".")[0]
        level: dict[str, int] = {}
        line: dict[str, int] = {}
        for row, (lineno, units) in enumerate(rows):
            depth = len(rows) - 1 - row
            for unit in units:
                if unit.split(".")[0] != package:
                    raise ValueError(f"{where}:{lineno}: unit {unit!r} is not in {package!r}")
                if unit in level:
                    raise ValueError(f"{where}:{lineno}: unit {unit!r} named twice")
                level[unit], line[unit] = depth, lineno
        if package in out:
            raise ValueError(f"{where}: a second layers block for {package!r}")
        out[package] = Layers(level, line)
    return out


def modules(package: str) -> dict[str, Path]:
    """Dotted module name -> file, for every module of ``package`` (a package is its __init__)."""
    out = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def unit_of(module: str, layers: Layers) -> str | None:
    """The most specific unit holding ``module`` (a package's root unit holds only itself)."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        name = ".".join(parts[:n])
        if name in layers.level and (name == module or n > 1):
            return name
    return None


def imports(path: Path, module: str, known: dict[str, Path]) -> list[tuple[int, str]]:
    """``(line, imported module)`` of every import in a file, resolved to the most specific
    known module (``from a.b import c`` is ``a.b.c`` when that is a module, else ``a.b``)."""
    source = path.read_text()
    out: list[tuple[int, str]] = []

    def resolve(name: str) -> str | None:
        while name and name not in known:
            name = name.rpartition(".")[0]
        return name or None

    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(source, str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".")
                anchor = anchor[: len(anchor) - node.level + (1 if is_package else 0)]
                base = ".".join([*anchor, *([base] if base else [])])
            names = [f"{base}.{a.name}" for a in node.names]
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute | ast.Name)
            and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            names = [node.args[0].value]
        for name in names:
            target = resolve(name)
            if target is not None and target != module:
                out.append((node.lineno, target))
    return out


def violations(package: str, layers: Layers) -> list[str]:
    """One line per import that points up (or sideways to a peer) in ``package``'s layers."""
    known = modules(package)
    out = []
    for module, path in known.items():
        own = unit_of(module, layers)
        if own is None:
            out.append(f"{path.relative_to(ROOT)}: module {module} is in no layer of DESIGN.md")
            continue
        for lineno, target in sorted(imports(path, module, known)):
            other = unit_of(target, layers)
            if other is None or other == own:
                continue
            if layers.level[other] >= layers.level[own]:
                kind = "a peer" if layers.level[other] == layers.level[own] else "a layer above"
                out.append(
                    f"{path.relative_to(ROOT)}:{lineno}: {module} ({own}) imports {target} "
                    f"({other}, {kind}: DESIGN.md line {layers.line[other]})"
                )
    return out


@pytest.fixture(scope="module")
def design_layers() -> dict[str, Layers]:
    return read_layers(DESIGN.read_text())


def test_design_states_the_layers_of_every_package(design_layers: dict[str, Layers]) -> None:
    assert set(design_layers) == set(PACKAGES)
    for package, layers in design_layers.items():
        known = modules(package)
        stale = [u for u in layers.level if not any(m == u or m.startswith(u + ".") for m in known)]
        assert not stale, f"DESIGN.md names units that are no modules of {package}: {stale}"


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_points_up(package: str, design_layers: dict[str, Layers]) -> None:
    found = violations(package, design_layers[package])
    assert not found, "imports against docs/DESIGN.md's layer order:\n" + "\n".join(found)


@pytest.mark.parametrize("package", PACKAGES)
def test_no_folder_holds_more_than_twenty_modules(package: str) -> None:
    counts = {}
    for folder in [ROOT / package, *(ROOT / package).rglob("*")]:
        if folder.is_dir() and folder.name != "__pycache__":
            n = sum(1 for f in folder.glob("*.py") if f.name != "__init__.py")
            counts[str(folder.relative_to(ROOT))] = n
    crowded = {k: v for k, v in counts.items() if v > MAX_MODULES_PER_FOLDER}
    assert not crowded, f"folders over {MAX_MODULES_PER_FOLDER} modules: {crowded}"


def test_layers_block_errors_name_the_line() -> None:
    with pytest.raises(ValueError, match=r"x\.md:3: unit 'pkg.a' named twice"):
        read_layers("```layers\npkg.a\npkg.a\n```\n", "x.md")
    with pytest.raises(ValueError, match=r"x\.md:3: unit 'other.b' is not in 'pkg'"):
        read_layers("```layers\npkg.a\nother.b\n```\n", "x.md")


def test_an_upward_import_of_each_kind_is_found(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A fake package with one upward import of each kind (module level, function level,
    TYPE_CHECKING, relative, importlib) and one downward import: five violations exactly."""
    pkg = tmp_path / "fakepkg"
    (pkg / "low").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "top.py").write_text("import fakepkg.low.a\n")
    (pkg / "low" / "__init__.py").write_text("")
    (pkg / "low" / "a.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "import importlib\n"
        "from fakepkg import top\n"
        "def f():\n    from fakepkg.top import x\n"
        "if TYPE_CHECKING:\n    import fakepkg.top\n"
        "from .. import top as t\n"
        "m = importlib.import_module('fakepkg.top')\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    layers = read_layers("```layers\nfakepkg\nfakepkg.top\nfakepkg.low\n```\n")["fakepkg"]
    found = violations("fakepkg", layers)
    assert len(found) == 5, found
    assert all("fakepkg.low.a (fakepkg.low) imports fakepkg.top" in f for f in found)
    assert [int(re.search(r"a\.py:(\d+)", f).group(1)) for f in found] == [3, 5, 7, 8, 9]


TOP_LEVEL = ("annotate", "app", "bench", "launch", "model", "scenes", "tools")
"""Every top-level package (and ``launch.py``) of the project; tests/ sits above them all."""


def read_package_order(text: str, where: str = "docs/DESIGN.md") -> dict[str, tuple[int, int]]:
    """The fenced ``packages`` block of a markdown text: top-level package -> ``(layer counted
    from the bottom, its line)``; packages on one line are peers.

    Raises:
        ValueError: no block, or a package named twice (names the line).
    """
    lines = text.splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == "```packages")
    except StopIteration:
        raise ValueError(f"{where}: no ```packages block") from None
    rows = []
    for i in range(start + 1, len(lines)):
        if lines[i].strip() == "```":
            break
        names = lines[i].split("#", 1)[0].split()
        if names:
            rows.append((i + 1, names))
    out: dict[str, tuple[int, int]] = {}
    for row, (lineno, names) in enumerate(rows):
        for name in names:
            if name in out:
                raise ValueError(f"{where}:{lineno}: package {name!r} named twice")
            out[name] = (len(rows) - 1 - row, lineno)
    return out


def package_violations(order: dict[str, tuple[int, int]], root: Path = ROOT) -> list[str]:
    """One line per import of one top-level package by another at its level or above."""
    out = []
    for top in order:
        files = [root / f"{top}.py"] if (root / f"{top}.py").is_file() else []
        files += sorted(p for p in (root / top).rglob("*.py") if "__pycache__" not in p.parts)
        for path in files:
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    other = name.split(".")[0]
                    if other == top or other not in order:
                        continue
                    if order[other][0] >= order[top][0]:
                        out.append(
                            f"{path.relative_to(root)}:{node.lineno}: {top} imports {name} "
                            f"({other}: DESIGN.md line {order[other][1]}, not below {top})"
                        )
    return out


def test_every_top_level_package_keeps_the_package_order() -> None:
    """DESIGN.md's ``packages`` block orders every top-level package; none imports one at its
    level or above (scenes at the bottom, the model and the annotation store on it, the app,
    launch.py, the benchmarks and tools on top)."""
    order = read_package_order(DESIGN.read_text())
    assert sorted(order) == sorted(TOP_LEVEL)
    found = package_violations(order)
    assert not found, "imports against DESIGN.md's package order:\n" + "\n".join(found)


def test_an_upward_import_between_packages_is_found(tmp_path: Path) -> None:
    """A fake tree where the bottom package imports the top one, and two peers import each
    other: three violations, each naming its file and line."""
    for name in ("low", "mid_a", "mid_b", "high"):
        (tmp_path / name).mkdir()
    (tmp_path / "low" / "__init__.py").write_text("import os\nfrom high import x\n")
    (tmp_path / "mid_a" / "m.py").write_text("import low\nimport mid_b.m\n")
    (tmp_path / "mid_b" / "m.py").write_text("from mid_a import m\n")
    (tmp_path / "high" / "__init__.py").write_text("import mid_a, low\n")
    order = read_package_order("```packages\nhigh\nmid_a mid_b\nlow\n```\n")
    found = package_violations(order, tmp_path)
    assert sorted(f.split(":")[0] for f in found) == [
        "low/__init__.py",
        "mid_a/m.py",
        "mid_b/m.py",
    ], found
