"""The live monitor in a real browser: ``rtseg live sim://synth --monitor`` as a
subprocess, its page opened in headless Chromium (Debian's ``chromium``, driven over the
DevTools protocol by ``rtseg.monitor.headless``).  The test waits for the session's first
cut and its behaviour line on stdout, then checks the page's DOM holds that cut and that
behaviour name, and takes a screenshot.  Skipped where no Chromium or aiohttp exists.
"""

from __future__ import annotations

import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("aiohttp", reason="the monitor needs aiohttp (rtseg[monitor])")

from rtseg.monitor.headless import HeadlessPage, find_chromium  # noqa: E402

pytestmark = pytest.mark.skipif(find_chromium() is None,
                                reason="no chromium on PATH (apt-get install chromium)")

CUT = re.compile(r"^cut #(\d+)\s+(\w+)\s+segment (\d+)")
BEHAVIOUR = re.compile(r'^behaviour\s+(\S+) "([^"]+)" segment (\d+)')
URL = re.compile(r"live monitor at (http://\S+)")


class Lines:
    """The lines of a stream, collected on a thread."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line.rstrip("\n"))

    def wait(self, pattern: re.Pattern, timeout: float, after: int = 0) -> re.Match:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in self.lines[after:]:
                m = pattern.search(line)
                if m:
                    return m
            time.sleep(0.05)
        raise AssertionError(f"no line matching {pattern.pattern}: {self.lines[-10:]}")


@pytest.fixture(scope="module")
def library(tmp_path_factory) -> str:
    from rtseg.commands.demo import demo_library
    from rtseg.live.config import load_session_config
    path, _ = demo_library(0, load_session_config(), str(tmp_path_factory.mktemp("lib")))
    return path


def test_page_shows_the_cut_and_behaviour_the_session_printed(library, tmp_path):
    exe = Path(sys.executable).with_name("rtseg")
    proc = subprocess.Popen(
        [str(exe), "live", "sim://synth?script=idle:4,walk:6,punch:6&speed=2&seed=1",
         "--monitor", "127.0.0.1:0", "--no-osc", "--behaviours", library, "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = Lines(proc.stdout), Lines(proc.stderr)
        url = err.wait(URL, 60).group(1)
        with HeadlessPage(url) as page:
            cut = out.wait(CUT, 30)
            event, method, segment = cut.group(1), cut.group(2), cut.group(3)
            named = None
            deadline = time.monotonic() + 20
            while named is None and time.monotonic() < deadline:   # its behaviour line
                for line in out.lines:
                    m = BEHAVIOUR.search(line)
                    if m and m.group(3) == segment:
                        named = m.group(2)
                time.sleep(0.05)
            assert named, f"no behaviour line for segment {segment}: {out.lines}"
            li = page.wait_for(
                f"(() => {{ const li = document.querySelector("
                f"'#cuts li[data-segment=\"{segment}\"]'); "
                f"return li && li.textContent.includes('{named}') && li.textContent; }})()",
                timeout=15)
            assert f"#{event}" in li and method in li and f"segment {segment}" in li
            bands = page.evaluate("[...document.querySelectorAll('#timeline .band')]"
                                  ".map(b => b.textContent)")
            assert named in bands
            joints = page.evaluate("document.querySelectorAll('#sensors .joint').length")
            assert joints == 17
            assert "17 of 17 online" in page.evaluate("document.getElementById('online')"
                                                      ".textContent")
            # one point per detector block (0.5 s at the defaults): the statistic keeps
            # coming after the first cut, however soon that came
            points = page.wait_for("window.rtsegMonitor.stat.length >= 5 && "
                                   "window.rtsegMonitor.stat.length", timeout=15)
            assert points >= 5
            shot = tmp_path / "monitor.png"
            size = page.screenshot(shot)
            data = shot.read_bytes()
            assert data[:8] == b"\x89PNG\r\n\x1a\n" and size == len(data) > 20_000
    finally:
        proc.terminate()
        proc.wait(20)
    assert proc.returncode == 0
