"""Headless Chromium driven through the DevTools protocol: open a page, screenshot it, list the
requests it made. The viewer's tests and benchmark use it to look at what a browser draws.

    with Browser() as b:
        b.open("http://127.0.0.1:8080")
        image, seconds = b.settled_canvas(minimum=0.03)   # the 3D view (H, W, 3) uint8, once drawn
"""

from __future__ import annotations

import base64
import io
import json
import shutil
import socket
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
         "--disable-quic", "--no-first-run", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", "--hide-scrollbars", "--remote-debugging-address=127.0.0.1"]


class Browser:
    """A headless Chromium with one page of ``width`` x ``height`` pixels (closed by :meth:`close`)."""

    def __init__(self, width: int = 1000, height: int = 700, binary: Path = CHROMIUM, timeout: float = 20.0):
        from websockets.sync.client import connect

        self.profile = tempfile.mkdtemp(prefix="manifoldgen-chromium-")
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self.process = subprocess.Popen([str(binary), *FLAGS, f"--remote-debugging-port={port}",
                                         f"--user-data-dir={self.profile}", f"--window-size={width},{height}",
                                         "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + timeout
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=2) as r:
                    pages = [p for p in json.load(r) if p["type"] == "page"]
                if pages:
                    break
            except OSError:
                pass
            if time.monotonic() > deadline or self.process.poll() is not None:
                self.close()
                raise RuntimeError(f"{binary} did not open its DevTools port within {timeout} s")
            time.sleep(0.1)
        self.socket = connect(pages[0]["webSocketDebuggerUrl"], max_size=None, open_timeout=timeout)
        self.events: list[dict] = []
        self._id = 0
        self.call("Page.enable")
        self.call("Network.enable")

    def call(self, method: str, **params) -> dict:
        """Send one DevTools command and return its result (events met on the way are kept)."""
        self._id += 1
        self.socket.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            message = json.loads(self.socket.recv(timeout=60))
            if message.get("id") == self._id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message["result"]
            self.events.append(message)

    def open(self, url: str) -> None:
        """Navigate to ``url`` (forgetting earlier events)."""
        self.events.clear()
        self.opened = time.monotonic()
        self.call("Page.navigate", url=url)

    def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page."""
        return self.call("Runtime.evaluate", expression=expression, returnByValue=True)["result"].get("value")

    def screenshot(self) -> np.ndarray:
        """(H, W, 3) uint8 RGB of the page as drawn now."""
        import matplotlib.image

        png = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return (matplotlib.image.imread(io.BytesIO(png), format="png")[..., :3] * 255).round().astype(np.uint8)

    def canvas(self) -> np.ndarray:
        """The screenshot cropped to the page's largest canvas (the 3D view), viser's notices (such as
        "software WebGL rendering detected") hidden first."""
        self.evaluate("document.querySelectorAll('.mantine-Notifications-root').forEach(e => e.style.display = 'none')")
        box = self.evaluate("JSON.stringify([...document.querySelectorAll('canvas')].map(c => "
                            "c.getBoundingClientRect()).sort((a, b) => b.width * b.height - a.width * a.height)[0])")
        image = self.screenshot()
        if box in (None, "null"):
            return image[:0, :0]
        r = json.loads(box)
        return image[int(r["y"]):int(r["y"] + r["height"]), int(r["x"]):int(r["x"] + r["width"])]

    def settled_canvas(self, minimum: float = 0.0, timeout: float = 60.0) -> tuple[np.ndarray, float]:
        """Poll the 3D view until at least ``minimum`` of it is drawn (:func:`drawn_fraction`) and two
        polls in a row agree within 5 %; returns the last image and the seconds since :meth:`open`."""
        previous = -1.0
        while True:
            image = self.canvas()
            fraction = drawn_fraction(image)
            seconds = time.monotonic() - self.opened
            if image.size and fraction >= minimum and abs(fraction - previous) <= 0.05 * max(previous, 1e-3):
                return image, seconds
            if seconds > timeout:
                raise TimeoutError(f"the page drew {fraction:.1%} of its 3D view after {timeout:.0f} s "
                                   f"(waiting for {minimum:.1%})")
            previous = fraction
            time.sleep(0.2)

    def requests(self) -> list[str]:
        """URLs the page requested since :meth:`open`."""
        return [e["params"]["request"]["url"] for e in self.events if e.get("method") == "Network.requestWillBeSent"]

    def close(self) -> None:
        if getattr(self, "socket", None) is not None:
            self.socket.close()
        self.process.terminate()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def drawn_fraction(image: np.ndarray, background: np.ndarray | None = None, threshold: int = 40) -> float:
    """Fraction of pixels of ``image (H, W, 3)`` that differ from ``background`` (same shape; default:
    the image's most common colour) by more than ``threshold`` in some channel."""
    if image.size == 0:
        return 0.0
    if background is None:
        colours, counts = np.unique(image.reshape(-1, 3), axis=0, return_counts=True)
        background = colours[np.argmax(counts)]
    return float(np.mean(np.abs(image.astype(int) - background.astype(int)).max(axis=-1) > threshold))
