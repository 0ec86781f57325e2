"""The README's own commands, run or parsed.

Every command of the README's fenced shell blocks (```sh, ```bash, ```console; in a
console block only the lines starting with ``$ ``) is collected, one test each:

- Set-up commands are not run: lines starting with ``python3 -m venv``, ``pip `` or
  ``. .venv`` (whole lines joined by ``&&`` count as one), and the test command itself
  (``python3 -m pytest``).  Every other command must start with ``rtseg``.
- A block with no marker is run with ``bash -c`` (a timeout of ``TIMEOUT_S`` each) and
  must exit 0.  It therefore has to be bounded in the README itself
  (``rtseg demo --speed 4``, ``rtseg live sim://synth --duration 3``).
- A block preceded by an HTML comment ``<!-- needs: WHAT -->`` (the line just before the
  fence, blank lines allowed) is handled by the allow-list ``NEEDS`` below:

  ``data``     runs when ``../shared/data`` (beside the checkout, or ``$RTSEG_DATA``) is
               there, else the test skips saying so; parsed in both cases.
  ``suit``     needs hardware or a sender on the network: parsed only.
  ``network``  needs a peer on the network (a Dask scheduler, ...): parsed only.
  ``dask``     starts a local Dask cluster (~25 s on two cores, over this test's time
               budget): parsed only.

  A marker not in ``NEEDS`` fails the test.
- "Parsed" means ``rtseg.cli.build_parser().parse_args(argv)`` accepts the command's
  arguments (split with ``shlex``, shell comments dropped): parsing builds no session,
  opens no source and starts nothing.

The commands run in a scratch folder ``WORK/checkout`` whose ``WORK/shared/data`` links
to the data folder, so ``../shared/data`` resolves as in a checkout and files the
commands write (``results.jsonl``) stay out of the repository.  The ``rtseg`` on ``PATH``
is the one of the running interpreter's environment.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
DATA = Path(os.environ.get("RTSEG_DATA", REPO.parent / "shared" / "data"))
TIMEOUT_S = 45

#: marker -> (what it does, reason)
NEEDS = {
    "data": ("run", "needs ../shared/data"),
    "suit": ("parse", "needs a suit or a sender on the network"),
    "network": ("parse", "needs a peer on the network"),
    "dask": ("parse", "starts a local Dask cluster, too slow for this test"),
}

SHELL_LANGS = {"sh", "bash", "console", "shell"}
SETUP_PREFIXES = ("python3 -m venv", "pip ", ". .venv", "python3 -m pytest")
MARKER = re.compile(r"^<!--\s*needs:\s*([\w-]+)\s*-->$")


@dataclass(frozen=True)
class Command:
    text: str
    line: int
    needs: str | None


def readme_commands(text: str) -> list[Command]:
    """Every command of the fenced shell blocks of ``text``, with its block's marker."""
    out: list[Command] = []
    lines = text.splitlines()
    i = 0
    marker: str | None = None
    while i < len(lines):
        stripped = lines[i].strip()
        m = MARKER.match(stripped)
        if m:
            marker = m.group(1)
            i += 1
            continue
        if stripped.startswith("```"):
            lang = stripped[3:].strip().lower()
            i += 1
            pending = ""
            start = i
            while i < len(lines) and not lines[i].strip().startswith("```"):
                raw = lines[i].rstrip()
                if lang in SHELL_LANGS:
                    if lang == "console":
                        raw = raw[2:] if raw.startswith("$ ") else ("" if not pending else raw)
                    if pending:
                        raw = pending + " " + raw.strip()
                    else:
                        start = i
                    if raw.endswith("\\"):
                        pending = raw[:-1].rstrip()
                    else:
                        pending = ""
                        if raw.strip() and not raw.strip().startswith("#"):
                            out.append(Command(raw.strip(), start + 1,
                                               marker))
                i += 1
            marker = None
            i += 1
            continue
        if stripped:
            marker = None
        i += 1
    return out


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))


def test_readme_has_commands() -> None:
    texts = [c.text for c in COMMANDS]
    assert any(t.startswith("rtseg demo") for t in texts)
    assert "python3 -m pytest -q" in [t.split("#")[0].strip() for t in texts]
    assert all(c.needs is None or c.needs in NEEDS for c in COMMANDS), \
        [(c.line, c.needs) for c in COMMANDS if c.needs not in NEEDS and c.needs]


def _argv(text: str) -> list[str]:
    return shlex.split(text, comments=True)


def _parse(argv: list[str]) -> None:
    from rtseg.cli import build_parser

    assert argv and argv[0] == "rtseg", f"not an rtseg command: {argv}"
    try:
        build_parser().parse_args(argv[1:])
    except SystemExit as exc:          # argparse refuses: exit status 2
        pytest.fail(f"rtseg's parser refused {shlex.join(argv)} (exit {exc.code})")


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("readme")
    (root / "checkout").mkdir()
    (root / "shared").mkdir()
    if DATA.is_dir():
        (root / "shared" / "data").symlink_to(DATA.resolve(), target_is_directory=True)
    return root / "checkout"


def _run(text: str, cwd: Path) -> None:
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    try:
        proc = subprocess.run(["bash", "-c", text], cwd=cwd, env=env, capture_output=True,
                              text=True, timeout=TIMEOUT_S, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        pytest.fail(f"README command still running after {TIMEOUT_S} s: {text}")
    assert proc.returncode == 0, (
        f"README command exited {proc.returncode}: {text}\n"
        f"stdout (end): {proc.stdout[-2000:]}\nstderr (end): {proc.stderr[-2000:]}")


@pytest.mark.parametrize("cmd", COMMANDS, ids=[f"L{c.line}" for c in COMMANDS])
def test_readme_command(cmd: Command, workdir: Path) -> None:
    text = cmd.text.split(" #")[0].strip() if " #" in cmd.text else cmd.text
    if text.startswith(SETUP_PREFIXES):
        pytest.skip("set-up or test command: not run")
    argv = _argv(cmd.text)
    _parse(argv)
    action, reason = NEEDS[cmd.needs] if cmd.needs else ("run", "")
    if action == "parse":
        return
    if cmd.needs == "data" and not DATA.is_dir():
        pytest.skip(f"{reason}: {DATA} is absent (parsed only)")
    _run(cmd.text, workdir)
