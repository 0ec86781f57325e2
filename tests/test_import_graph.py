"""The import graph and the package layout.

- Command modules (``rtseg/commands/``, ``rtseg/cli.py``) parse arguments and print;
  nothing else imports them, at module level or inside a function (a module's own
  ``main()``, its ``python -m`` entry point, may hand its arguments to the CLI).
- No import cycles between the modules of ``rtseg``, ``rtseg.drivers`` and
  ``rtseg.simulators`` (imports inside functions count: they tie modules together too).
- ``rtseg/`` and ``drivers/`` hold at most 6 plain modules beside their sub-packages; in
  no package do two sibling modules share a family prefix (``library_file`` beside
  ``library_learn``); every package's ``__init__`` says what it holds.
- Every package's ``__init__`` says what it may import (a paragraph starting "May import"
  that names modules and packages in double backquotes), and its modules import nothing
  else of rtseg but their own package."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: source folder -> the package it installs as (pyproject.toml)
PACKAGES = {"rtseg": "rtseg", "drivers": "rtseg.drivers", "simulators": "rtseg.simulators"}


def imported_modules(path: Path) -> set[str]:
    """Every absolute module name ``path`` imports anywhere (top level or in a function),
    but inside a function named ``main``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    entry = {id(n) for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name == "main"
             for n in ast.walk(f)}
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in entry:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def _is_command_module(rel: Path) -> bool:
    return rel.parts[:2] == ("rtseg", "commands") or rel.as_posix() == "rtseg/cli.py"


def test_no_module_outside_the_commands_imports_a_command_module():
    offenders = []
    for folder in PACKAGES:
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if _is_command_module(rel):
                continue
            bad = sorted(m for m in imported_modules(path)
                         if m == "rtseg.commands" or m.startswith("rtseg.commands.")
                         or m == "rtseg.cli")
            if bad:
                offenders.append(f"{rel}: {', '.join(bad)}")
    assert not offenders, "modules importing command modules:\n" + "\n".join(offenders)


def test_the_check_sees_a_function_level_import_but_not_the_main_entry(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def g():\n    from rtseg.commands.evaluate import Progress\n"
                 "def main():\n    from rtseg.cli import main\n")
    got = imported_modules(f)
    assert "rtseg.commands.evaluate" in got and "rtseg.cli" not in got


def module_files(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file, for every module of the three installed packages."""
    mods: dict[str, Path] = {}
    for folder, pkg in PACKAGES.items():
        for path in sorted((root / folder).rglob("*.py")):
            parts = path.relative_to(root / folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join((pkg,) + parts)] = path
    return mods


def import_edges(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules of ``mods`` it imports (``from pkg import name`` is an edge to
    ``pkg.name`` when that is a module, else to ``pkg``)."""
    edges: dict[str, set[str]] = {}
    for name, path in mods.items():
        out: set[str] = set()
        for m in imported_modules_all(path):
            while m and m not in mods:
                m = m.rpartition(".")[0]
            if m and m != name:
                out.add(m)
        edges[name] = out
    return edges


def imported_modules_all(path: Path) -> set[str]:
    """Every absolute module name ``path`` imports, ``main()`` included; for
    ``from a import b`` both ``a.b`` (when a module) and ``a`` are candidates: the caller
    keeps ``a.b`` when it names a module."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of two or more modules (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    for start in edges:
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = len(index)
        stack.append(start); on.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w); on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop(); on.discard(w); comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_no_import_cycles():
    found = cycles(import_edges(module_files()))
    assert not found, "import cycles:\n" + "\n".join(", ".join(c) for c in found)


def test_the_cycle_check_finds_a_function_level_cycle(tmp_path):
    pkg = tmp_path / "rtseg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from rtseg.b import f\n")
    (pkg / "b.py").write_text("def f():\n    from rtseg import a\n")
    (pkg / "c.py").write_text("import rtseg.a\n")
    for other in ("drivers", "simulators"):
        (tmp_path / other).mkdir()
    found = cycles(import_edges(module_files(tmp_path)))
    assert found == [["rtseg.a", "rtseg.b"]]


def _packages(folder: Path):
    yield folder
    for init in sorted(folder.rglob("__init__.py")):
        if init.parent != folder:
            yield init.parent


def _plain_modules(package: Path) -> list[str]:
    return sorted(p.stem for p in package.glob("*.py") if p.stem != "__init__")


def test_top_level_packages_hold_few_plain_modules():
    for folder in ("rtseg", "drivers"):
        plain = _plain_modules(ROOT / folder)
        assert len(plain) <= 6, f"{folder}/ holds {len(plain)} plain modules: {plain}"


def family(stem: str) -> str:
    """A module's family: its name up to the first underscore (a leading one ignored)."""
    return stem.lstrip("_").split("_")[0]


def test_no_two_sibling_modules_share_a_family_prefix():
    clashes = []
    for folder in PACKAGES:
        for package in _packages(ROOT / folder):
            seen: dict[str, str] = {}
            for stem in _plain_modules(package):
                f = family(stem)
                if f in seen and "_" in (stem + seen[f]).lstrip("_"):
                    clashes.append(f"{package.relative_to(ROOT)}: {seen[f]}, {stem}")
                seen.setdefault(f, stem)
    assert not clashes, "modules of one family side by side (make them a package):\n" + \
        "\n".join(clashes)
    assert family("library_file") == family("library_learn") != family("live")


def test_every_package_says_what_it_holds():
    silent = []
    for folder in PACKAGES:
        for package in _packages(ROOT / folder):
            init = package / "__init__.py"
            doc = ast.get_docstring(ast.parse(init.read_text(encoding="utf-8")))
            if not doc or len(doc.split()) < 8:
                silent.append(str(init.relative_to(ROOT)))
    assert not silent, "packages without a docstring saying what they hold: " + ", ".join(silent)


def test_pyproject_installs_every_package():
    import tomllib
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    present = {name for name, path in module_files().items() if path.name == "__init__.py"}
    assert present - listed == set(), f"packages missing from pyproject.toml: {sorted(present - listed)}"
    assert listed - present == {"rtseg.defaults"}


def stated_imports(doc: str) -> set[str] | None:
    """The modules a package's docstring says it may import: the ``rtseg...`` names in
    double backquotes of its paragraph starting "May import"; ``{"*"}`` for "any package";
    None when it has no such paragraph."""
    import re

    para = next((p for p in re.split(r"\n\s*\n", doc) if p.lstrip().startswith("May import")),
                None)
    if para is None:
        return None
    if "any package" in para:
        return {"*"}
    return set(re.findall(r"``(rtseg(?:\.\w+)*)``", para))


def allowed(package: str, target: str, stated: set[str]) -> bool:
    """Whether a module of ``package`` may import module ``target``: its own package and
    what lies below it, or a stated name and what lies below that; a stated ancestor of
    the package (``rtseg``) allows that module alone."""
    if "*" in stated or target == package or target.startswith(package + "."):
        return True
    for name in stated:
        if package.startswith(name + "."):
            if target == name:
                return True
        elif target == name or target.startswith(name + "."):
            return True
    return False


def test_every_package_keeps_to_what_it_may_import():
    mods = module_files()
    edges = import_edges(mods)
    rules: dict[str, set[str]] = {}
    unstated = []
    for name, path in mods.items():
        if path.name != "__init__.py" or name == "rtseg":   # the root holds everything
            continue
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        stated = stated_imports(doc)
        if stated is None:
            unstated.append(name)
            continue
        rules[name] = stated
    assert not unstated, "packages whose __init__ does not say what they may import " \
        "(a paragraph starting 'May import ``rtseg...``'): " + ", ".join(sorted(unstated))
    offenders = []
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        if package not in rules:
            continue
        for target in sorted(edges[name]):
            if not allowed(package, target, rules[package]):
                offenders.append(f"{name} imports {target}")
    assert not offenders, "imports their package's __init__ does not allow:\n" + \
        "\n".join(offenders)


def test_the_rule_check_reads_the_docstring_and_refuses_what_it_leaves_out():
    doc = "Holds things.\n\nMay import ``rtseg.core`` and ``rtseg`` (its version)."
    stated = stated_imports(doc)
    assert stated == {"rtseg.core", "rtseg"}
    assert allowed("rtseg.recording", "rtseg.core.events", stated)
    assert allowed("rtseg.recording", "rtseg", stated)
    assert allowed("rtseg.recording", "rtseg.recording.format", stated)
    assert not allowed("rtseg.recording", "rtseg.live.session", stated)
    assert stated_imports("Holds things, and says nothing of imports.") is None
