"""Headless Chromium driven through the DevTools protocol over a pipe (``--remote-debugging-pipe``: JSON
messages ended by NUL on file descriptors 3 and 4), so the tests need no WebSocket library and no
network. Used by the browser tests and by ``python -m tests.helpers.chromium`` (screenshots).

``Browser.find()`` locates the executable (``RBCHECK_CHROMIUM``, then chromium, chromium-browser,
google-chrome, google-chrome-stable on PATH); ``Browser().load(url, width)`` returns what the page did:
console errors and uncaught exceptions, failed requests, images that did not decode, links whose file
is missing, and the page's horizontal overflow at that width.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from urllib.parse import unquote, urlparse

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions",
         "--disable-default-apps", "--mute-audio", "--hide-scrollbars", "--remote-debugging-pipe"]
NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

# Everything the page shows as broken, measured in the page itself after load.
_AUDIT_JS = r"""
(() => {
  const imgs = [...document.images].map(i => ({src: i.getAttribute('src').slice(0, 80),
                                              ok: i.complete && i.naturalWidth > 0}));
  const links = [...document.querySelectorAll('a[href]')].map(a => a.href);
  const doc = document.documentElement;
  return JSON.stringify({imgs, links, scrollWidth: doc.scrollWidth, clientWidth: doc.clientWidth,
                         title: document.title, sortable: document.querySelectorAll('table.sortable').length});
})()
"""


class BrowserError(RuntimeError):
    pass


class Browser:
    """One headless Chromium with a fresh profile; a context manager."""

    @staticmethod
    def find() -> str | None:
        env = os.environ.get("RBCHECK_CHROMIUM")
        if env:
            return env if Path(env).is_file() else None
        return next((p for p in map(shutil.which, NAMES) if p), None)

    def __init__(self, executable: str | None = None, timeout_s: float = 60.0):
        exe = executable or self.find()
        if not exe:
            raise BrowserError("no Chromium found (install the Debian package 'chromium')")
        self.timeout_s = timeout_s
        self.profile = tempfile.mkdtemp(prefix="rbcheck-chromium-")
        to_chrome_r, self._w = os.pipe()
        self._r, from_chrome_w = os.pipe()
        # the child sees its read end as fd 3 and its write end as fd 4
        self.proc = subprocess.Popen(
            [exe, *FLAGS, f"--user-data-dir={self.profile}", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            pass_fds=(3, 4), preexec_fn=_dup_to(to_chrome_r, from_chrome_w))
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._buf = b""
        self._id = 0
        self._events = []
        self.session = self._attach()

    # --- protocol ---------------------------------------------------------------------------------
    def _send(self, method, params=None, session=None):
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        return self._id

    def _read_message(self, deadline):
        while b"\0" not in self._buf:
            if time.monotonic() > deadline:
                raise BrowserError("Chromium did not answer in time")
            import select
            ready, _, _ = select.select([self._r], [], [], 0.5)
            if ready:
                chunk = os.read(self._r, 1 << 20)
                if not chunk:
                    raise BrowserError("Chromium closed the pipe")
                self._buf += chunk
        raw, self._buf = self._buf.split(b"\0", 1)
        return json.loads(raw)

    def call(self, method, params=None, session="default"):
        sid = self.session if session == "default" else session
        want = self._send(method, params, sid)
        deadline = time.monotonic() + self.timeout_s
        while True:
            msg = self._read_message(deadline)
            if msg.get("id") == want:
                if "error" in msg:
                    raise BrowserError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            if "method" in msg:
                self._events.append(msg)

    def _attach(self):
        target = self.call("Target.createTarget", {"url": "about:blank"}, session=None)["targetId"]
        sid = self.call("Target.attachToTarget", {"targetId": target, "flatten": True},
                        session=None)["sessionId"]
        for domain in ("Page", "Runtime", "Log", "Network"):
            self.call(f"{domain}.enable", session=sid)
        return sid

    def _wait_event(self, name, timeout_s):
        deadline = time.monotonic() + timeout_s
        while True:
            for i, e in enumerate(self._events):
                if e["method"] == name:
                    return self._events.pop(i)
            self._events.append(self._read_message(deadline))

    # --- what the tests use -----------------------------------------------------------------------
    def load(self, url: str, width: int = 1400, height: int = 900,
             screenshot: str | Path | None = None) -> dict:
        """Load ``url`` at ``width`` px; returns ``{"errors": [...], "broken": [...], "overflow_px": int,
        "title": str, "sortable": int}``; writes a full-page PNG to ``screenshot`` when given."""
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1,
                                                          "mobile": False})
        self._events.clear()
        self.call("Page.navigate", {"url": url})
        self._wait_event("Page.loadEventFired", self.timeout_s)
        audit = json.loads(self.call("Runtime.evaluate", {"expression": _AUDIT_JS, "returnByValue": True})
                           ["result"]["value"])
        errors = self._page_errors()
        broken = [f"image {i['src']}" for i in audit["imgs"] if not i["ok"]]
        broken += [f"link {h}" for h in audit["links"] if _missing_file(h)]
        if screenshot is not None:
            self._screenshot(screenshot, width)
        return {"errors": errors, "broken": broken,
                "overflow_px": audit["scrollWidth"] - audit["clientWidth"], "title": audit["title"],
                "sortable": audit["sortable"]}

    def evaluate(self, expression: str):
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True})
        if "exceptionDetails" in r:
            raise BrowserError(f"{expression[:60]}: {r['exceptionDetails'].get('text')}")
        return r["result"].get("value")

    def _page_errors(self) -> list:
        out = []
        for e in self._events:
            p = e.get("params", {})
            if e["method"] == "Runtime.exceptionThrown":
                d = p["exceptionDetails"]
                out.append(f"exception: {d.get('exception', {}).get('description') or d.get('text')}")
            elif e["method"] == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                out.append("console: "
                           + " ".join(str(a.get("value", a.get("description"))) for a in p["args"]))
            elif e["method"] == "Log.entryAdded" and p["entry"]["level"] == "error":
                out.append(f"log: {p['entry']['text']} {p['entry'].get('url', '')}")
            elif e["method"] == "Network.loadingFailed" and not p.get("canceled"):
                out.append(f"request failed: {p.get('errorText')}")
        return out

    def _screenshot(self, path, width):
        h = self.evaluate("document.documentElement.scrollHeight")
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": int(h), "deviceScaleFactor": 1,
                                                          "mobile": False})
        data = self.call("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True})["data"]
        Path(path).write_bytes(base64.b64decode(data))

    def close(self):
        try:
            self._send("Browser.close")
            self.proc.wait(timeout=10)
        except Exception:  # noqa: BLE001 - closing: kill what did not stop
            self.proc.kill()
            self.proc.wait()
        finally:
            for fd in (self._r, self._w):
                try:
                    os.close(fd)
                except OSError:
                    pass
            shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _dup_to(read_fd, write_fd):
    def child():
        os.dup2(read_fd, 3)
        os.dup2(write_fd, 4)
    return child


def _missing_file(href: str) -> bool:
    """A file: link (fragment dropped) whose file does not exist."""
    u = urlparse(href)
    return u.scheme == "file" and not Path(unquote(u.path)).exists()


def screenshots(results_dir, out_dir, pages, widths=(1024, 1400)) -> list:
    """Screenshot ``pages`` of a results directory at each width into ``out_dir``; returns the paths."""
    out = []
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    with Browser() as b:
        for page in pages:
            for w in widths:
                p = Path(out_dir) / f"{Path(page).stem}-{w}.png"
                r = b.load(Path(results_dir, page).resolve().as_uri(), width=w, screenshot=p)
                print(f"{p}: errors {r['errors']}, broken {r['broken']}, overflow {r['overflow_px']} px")
                out.append(p)
    return out


if __name__ == "__main__":
    import sys
    screenshots(sys.argv[1], sys.argv[2], sys.argv[3:])
