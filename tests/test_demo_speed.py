"""``rtseg demo --speed``: frames go out faster on the performance's own clock, so
--duration, the cut times printed and the detector delays are performance time."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_demo_speed_prints_performance_time():
    proc = subprocess.run(
        [sys.executable, "-m", "rtseg.cli", "demo", "--speed", "4", "--duration", "8",
         "--script", "idle:3,walk:5", "--no-osc", "--methods", "pca"],
        capture_output=True, text=True, timeout=60, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    assert "performance time" in proc.stderr
    # 8 s of performance at 4x: the session lasts about 2 s of wall-clock time
    wall = float(re.search(r"session ended \(duration reached\) after ([\d.]+) s",
                           proc.stderr).group(1))
    assert 1.5 <= wall < 4.0, proc.stderr
    times = [float(m) for m in re.findall(r"^cut .* t=\s*([\d.]+) s", proc.stdout, re.M)]
    assert times, proc.stdout
    # the idle -> walk change is 3.0 s into the performance: the printed time is that, not
    # the ~0.75 s of wall-clock time it took to get there
    assert any(abs(t - 3.0) < 0.6 for t in times), times
