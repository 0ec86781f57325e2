"""A headless Chromium driven over the DevTools protocol, to look at the monitor page.

``HeadlessPage(url)`` starts ``chromium --headless`` (Debian's ``/usr/bin/chromium``, or
``$RTSEG_CHROMIUM``) with a private profile, no network services of its own
(``--disable-background-networking`` and the like) and ``--remote-debugging-port=0``;
the DevTools address is read from the profile's ``DevToolsActivePort`` file and spoken to
over a WebSocket (aiohttp's client).  ``evaluate(js)`` returns a JavaScript expression's
value, ``screenshot(path)`` writes a PNG, ``close()`` ends the browser.  The tests and
``benchmarks/live.py --monitor`` use it; :func:`find_chromium` is None where no browser
is installed.
"""

from __future__ import annotations

import asyncio
import base64
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import aiohttp

__all__ = ["HeadlessPage", "find_chromium"]


def find_chromium() -> str | None:
    """The Chromium executable (``$RTSEG_CHROMIUM``, chromium, chromium-browser,
    google-chrome), or None."""
    env = os.environ.get("RTSEG_CHROMIUM")
    if env:
        return env if os.access(env, os.X_OK) else None
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class HeadlessPage:
    """One headless Chromium showing ``url`` (see the module docstring)."""

    def __init__(self, url: str, width: int = 1280, height: int = 900,
                 timeout: float = 30.0) -> None:
        exe = find_chromium()
        if exe is None:
            raise FileNotFoundError("no chromium found (apt-get install chromium)")
        self._profile = tempfile.mkdtemp(prefix="rtseg-chromium-")
        self.proc = subprocess.Popen(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", "--disable-extensions",
             "--disable-dev-shm-usage", f"--window-size={width},{height}",
             "--remote-debugging-address=127.0.0.1", "--remote-debugging-port=0",
             f"--user-data-dir={self._profile}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self._loop = asyncio.new_event_loop()
        self._id = 0
        try:
            self._ws_url = self._devtools_page(timeout)
            self._run(self._connect())
            self.call("Page.enable")
            self.call("Page.navigate", url=url)
        except BaseException:
            self.close()
            raise

    def _devtools_page(self, timeout: float) -> str:
        port_file = Path(self._profile) / "DevToolsActivePort"
        deadline = time.monotonic() + timeout
        while not port_file.exists() or not port_file.read_text().strip():
            if self.proc.poll() is not None:
                raise RuntimeError(f"chromium exited with status {self.proc.returncode}")
            if time.monotonic() > deadline:
                raise TimeoutError("chromium did not open its DevTools port")
            time.sleep(0.05)
        port = int(port_file.read_text().split()[0])

        async def targets() -> list[dict]:
            async with aiohttp.ClientSession() as s:
                async with s.get(f"http://127.0.0.1:{port}/json/list") as r:
                    return await r.json()
        for _ in range(100):
            pages = [t for t in self._run(targets()) if t.get("type") == "page"]
            if pages:
                return pages[0]["webSocketDebuggerUrl"]
            time.sleep(0.05)
        raise TimeoutError("chromium has no page target")

    def _run(self, coro: Any) -> Any:
        return self._loop.run_until_complete(coro)

    async def _connect(self) -> None:
        self._session = aiohttp.ClientSession()
        self._ws = await self._session.ws_connect(self._ws_url, max_msg_size=64 << 20)

    async def _call(self, method: str, params: dict) -> dict:
        self._id += 1
        my = self._id
        await self._ws.send_json({"id": my, "method": method, "params": params})
        while True:
            msg = await self._ws.receive_json(timeout=30)
            if msg.get("id") == my:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def call(self, method: str, **params: Any) -> dict:
        """One DevTools command; its result."""
        return self._run(self._call(method, params))

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (JSON-able values)."""
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in r:
            raise RuntimeError(f"page script failed: {r['exceptionDetails'].get('text')}")
        return r.get("result", {}).get("value")

    def wait_for(self, expression: str, timeout: float = 30.0, every: float = 0.2) -> Any:
        """Poll ``expression`` until it is truthy; its value (TimeoutError otherwise)."""
        deadline = time.monotonic() + timeout
        while True:
            v = self.evaluate(expression)
            if v:
                return v
            if time.monotonic() > deadline:
                raise TimeoutError(f"page never satisfied: {expression}")
            time.sleep(every)

    def screenshot(self, path: str | Path) -> int:
        """Write a PNG of the page to ``path``; its size in bytes."""
        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        Path(path).write_bytes(data)
        return len(data)

    def close(self) -> None:
        try:
            if getattr(self, "_ws", None) is not None:
                self._run(self._ws.close())
            if getattr(self, "_session", None) is not None:
                self._run(self._session.close())
        except Exception:
            pass
        self._loop.close()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> "HeadlessPage":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
