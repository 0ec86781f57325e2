"""The import graph: command modules (``rtseg/commands/``, ``rtseg/cli.py``) parse arguments
and print; nothing else imports them, at module level or inside a function (a module's own
``main()``, its ``python -m`` entry point, may hand its arguments to the CLI)."""

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
