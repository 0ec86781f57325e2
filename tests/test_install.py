"""A normal (non-editable) install carries its default configuration.

``config/`` is the single source of the defaults; the build maps it into the package as
``rtseg.defaults``.  These tests build the package tree with setuptools' ``build_py`` (what
``pip wheel`` packs, offline and in under a second), check that the shipped defaults are
exactly the files of ``config/`` (so the two cannot drift), and run ``rtseg live`` and
``rtseg segment`` from that tree outside the checkout.  ``.ci/run`` also builds a real wheel
and installs it in a fresh venv.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from rtseg.config import config_dir

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    """The installed-package tree of the project, as a wheel would hold it."""
    lib = tmp_path_factory.mktemp("lib")
    r = subprocess.run([sys.executable, "-c", "from setuptools import setup; setup()", "-q",
                        "build_py", "--build-lib", str(lib)],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return lib


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.suffix == ".toml"}


def test_shipped_defaults_are_exactly_the_config_folder(built):
    shipped = _files(built / "rtseg" / "defaults")
    assert shipped, "no configuration in the package"
    assert shipped == _files(REPO / "config")
    # config/ holds only TOML files (anything else would silently not ship)
    assert {p.suffix for p in (REPO / "config").iterdir() if p.is_file()} == {".toml"}


def test_checkout_reads_the_config_folder():
    assert _files(config_dir()) == _files(REPO / "config")


def _run_installed(built: Path, cwd: Path, *argv: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(built))
    return subprocess.run([sys.executable, "-m", "rtseg.cli", *argv], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=60)


def test_installed_tree_runs_live_and_segment_outside_the_checkout(built, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(built))
    where = subprocess.run(
        [sys.executable, "-c", "import rtseg, rtseg.config as c; print(rtseg.__file__); "
         "print(c.config_dir())"], cwd=tmp_path, env=env, capture_output=True, text=True)
    pkg, cfg = where.stdout.split()
    assert Path(pkg).is_relative_to(built) and Path(cfg) == built / "rtseg" / "defaults"
    assert not (built / "config").exists()

    r = _run_installed(built, tmp_path, "live", "sim://synth", "--duration", "1", "--no-osc",
                       "--quiet")
    assert r.returncode == 0, r.stderr
    assert "frames received" in r.stderr

    take = tmp_path / "synth.npz"
    subprocess.run([sys.executable, "-c",
                    "import sys\nfrom rtseg.simulators.synth.motion import synthesize\n"
                    "from rtseg.drivers.readers.npz_take import write_npz\n"
                    "write_npz(sys.argv[1], synthesize('idle:3,walk:4', seed=1).take)",
                    str(take)], cwd=tmp_path, env=env, check=True, timeout=60)
    r = _run_installed(built, tmp_path, "segment", str(take), "--method", "pca",
                       "--format", "json")
    assert r.returncode == 0, r.stderr
    assert '"pca"' in r.stdout


def test_monitor_page_and_charting_library_ship(built):
    """The live monitor's page, uPlot and its licence are in the package (no CDN)."""
    src = REPO / "rtseg" / "monitor" / "static"
    shipped = built / "rtseg" / "monitor" / "static"
    names = {p.name for p in src.iterdir()}
    assert {"index.html", "monitor.js", "uPlot.iife.min.js", "uPlot.min.css",
            "uPlot.LICENSE"} <= names
    for name in names:
        assert (shipped / name).read_bytes() == (src / name).read_bytes(), name
    page = (src / "index.html").read_text() + (src / "monitor.js").read_text()
    assert "http://" not in page.replace("ws://", "") and "https://" not in page
