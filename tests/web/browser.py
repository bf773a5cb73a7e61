"""Headless Chromium for the browser tests and the benchmark: a localhost HTTP server (in a
thread) serving web/ at /web/ and chosen files at /files/<name>, and Debian's Chromium driven
by web/tools/browser_driver.mjs (playwright-core) over JSON lines.

    with Browser() as browser:
        url = browser.serve_file(path)             # → /files/<name>
        state = browser.open(browser.page_url(url, debug="diffuse-indirect"), 160, 120)
        value = browser.eval("window.voxgi.timings")

``missing_prerequisites()`` says what `make test` should have installed (Debian's chromium,
web/node_modules): the tests fail with it, they never skip.
"""
from __future__ import annotations

import base64
import functools
import http.server
import json
import os
import pathlib
import queue
import shutil
import subprocess
import threading
import urllib.parse

import numpy as np

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
WEB_DIR = REPO_ROOT / "web"
DRIVER = WEB_DIR / "tools" / "browser_driver.mjs"
CHROMIUM = os.environ.get("VOXGI_CHROMIUM", "/usr/bin/chromium")


def missing_prerequisites() -> list[str]:
    """What the browser tests need and this machine lacks (`make web-deps` installs it)."""
    missing = []
    if not os.path.exists(CHROMIUM):
        missing.append(f"{CHROMIUM} (Debian's chromium: apt-get install chromium)")
    if shutil.which("node") is None:
        missing.append("node (Node.js)")
    for package in ("three", "playwright-core"):
        if not (WEB_DIR / "node_modules" / package / "package.json").exists():
            missing.append(f"web/node_modules/{package} (npm ci in web/)")
    return missing


class _Handler(http.server.SimpleHTTPRequestHandler):
    files: dict[str, pathlib.Path] = {}

    def translate_path(self, path):
        path = urllib.parse.unquote(urllib.parse.urlsplit(path).path)
        if path.startswith("/files/"):
            target = self.files.get(path[len("/files/"):])
            return str(target) if target is not None else "/nonexistent"
        if path.startswith("/web/"):
            rel = pathlib.PurePosixPath(path[len("/web/"):])
            if ".." in rel.parts:
                return "/nonexistent"
            return str(WEB_DIR / rel)
        return "/nonexistent"

    def end_headers(self):
        self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def log_message(self, *args):  # quiet
        pass


class Browser:
    """The server and one Chromium (one page open at a time)."""

    def __init__(self, timeout: float = 300.0):
        missing = missing_prerequisites()
        if missing:
            raise RuntimeError("the browser tests need " + ", ".join(missing)
                               + ": `make test` installs them (Makefile target web-deps)")
        self.timeout = timeout
        handler = type("Handler", (_Handler,), {"files": {}})
        self._files = handler.files
        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.port = self.server.server_address[1]
        self._server_thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self._server_thread.start()
        self.process = subprocess.Popen(["node", str(DRIVER)], cwd=str(WEB_DIR), stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self._lines: queue.Queue = queue.Queue()
        self._stderr: list[str] = []
        threading.Thread(target=self._pump, args=(self.process.stdout, self._lines.put),
                         daemon=True).start()
        threading.Thread(target=self._pump, args=(self.process.stderr, self._stderr.append),
                         daemon=True).start()
        self._next_id = 0

    @staticmethod
    def _pump(stream, sink):
        for line in stream:
            sink(line)
        sink(None)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def serve_file(self, path, name: str | None = None) -> str:
        """URL path (/files/<name>) at which the server hands out ``path``."""
        path = pathlib.Path(path)
        name = name or path.name
        self._files[name] = path
        return f"/files/{urllib.parse.quote(name)}"

    def page_url(self, file_url: str, **params) -> str:
        query = urllib.parse.urlencode({"file": file_url, **params})
        return f"http://127.0.0.1:{self.port}/web/index.html?{query}"

    def request(self, op: str, timeout: float | None = None, **fields):
        self._next_id += 1
        request_id = self._next_id
        self.process.stdin.write(json.dumps({"id": request_id, "op": op, **fields}) + "\n")
        self.process.stdin.flush()
        while True:
            try:
                line = self._lines.get(timeout=timeout or self.timeout)
            except queue.Empty:
                raise TimeoutError(f"browser driver: no answer to {op} in {timeout or self.timeout} s; "
                                   f"stderr: {''.join(self._stderr)[-2000:]}") from None
            if line is None:
                raise RuntimeError(f"browser driver exited ({self.process.poll()}): "
                                   f"{''.join(self._stderr)[-4000:]}")
            reply = json.loads(line)
            if reply.get("id") != request_id:
                continue
            if not reply["ok"]:
                raise RuntimeError(f"browser {op} failed: {reply['error']}\nconsole: "
                                   f"{reply.get('console')}\npage errors: {reply.get('pageErrors')}")
            return reply["result"]

    def open(self, url: str, width: int = 640, height: int = 480, timeout: float | None = None) -> dict:
        """Open the page in a fresh context; {state, error, timings, probeErrors, console, pageErrors}."""
        t = timeout or self.timeout
        return self.request("open", timeout=t + 10, url=url, width=int(width), height=int(height),
                            page_timeout=int(t * 1000))

    def eval(self, expr: str, timeout: float | None = None):
        return self.request("eval", timeout=timeout, expr=expr)

    def screenshot(self, path) -> None:
        self.request("screenshot", path=str(path))

    def console(self) -> dict:
        return self.request("console")

    def read_pass(self, mode: str) -> np.ndarray:
        """(H, W, 4) float32 linear output of a debug mode, row 0 at the top."""
        out = self.eval(f"window.voxgi.readPass({json.dumps(mode)})")
        data = np.frombuffer(base64.b64decode(out["data"]), np.float32)
        return data.reshape(out["height"], out["width"], 4)[::-1].copy()

    def evaluate_in_frame(self, points, normals, volume: int = 0) -> np.ndarray:
        """(N, 3) float32: the shader's query at points / unit normals in volume's grid frame."""
        p = json.dumps(np.asarray(points, np.float64).ravel().tolist())
        n = json.dumps(np.asarray(normals, np.float64).ravel().tolist())
        out = self.eval(f"window.voxgi.evaluateInFrame({int(volume)}, {p}, {n})")
        return np.frombuffer(base64.b64decode(out), np.float32).reshape(-1, 3).copy()

    def close(self):
        if self.process.poll() is None:
            try:
                self.request("quit", timeout=30)
            except Exception:  # noqa: BLE001 - closing anyway
                pass
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.server.shutdown()
        self.server.server_close()


@functools.lru_cache(maxsize=None)
def chromium_version() -> str:
    return subprocess.run([CHROMIUM, "--version"], capture_output=True, text=True).stdout.strip()
