"""A view seen from a headless browser: the system's Chromium driven by Playwright (never a
downloaded one), for the tests, the latency benchmark and the documentation's pictures. It opens
the page, records the batches of messages the page's websocket worker hands to the page (viser
decodes its frames in a Web Worker), reads back what a scene node received, takes screenshots,
and drags the goal the way the page does (a ``TransformControlsUpdateMessage`` over a websocket)
to time a drag to the next frame drawn."""

from __future__ import annotations

import os
import shutil
import tempfile

import numpy as np

__all__ = ["CHROMIUM_ARGS", "find_chromium", "HeadlessBrowser"]

# A closed, quiet, headless Chromium: no sandbox (containers, root), no GPU (software WebGL),
# no QUIC, first-run, background, component-update or sync traffic.
CHROMIUM_ARGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync")


def find_chromium() -> str | None:
    """The system's Chromium executable (``chromium`` on the PATH, or /usr/bin/chromium), or None."""
    for candidate in (shutil.which("chromium"), shutil.which("chromium-browser"), "/usr/bin/chromium"):
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    return None


# Installed in the page before its scripts run: every batch of messages viser's websocket worker
# hands to the page is kept, with the time it arrived (performance.now(), ms).
_RECORD_JS = """
(() => {
  const Native = window.Worker;
  window.__softplan = {batches: []};
  window.Worker = function (...args) {
    const worker = new Native(...args);
    worker.addEventListener("message", (e) => {
      if (e.data && e.data.type === "message_batch")
        window.__softplan.batches.push({t: performance.now(), messages: e.data.messages});
    });
    return worker;
  };
  window.Worker.prototype = Native.prototype;
})();
"""

# The values a scene node received for one property, batch by batch from batch `since` on: its
# creation's props or its updates (typed arrays as plain arrays), with each batch's arrival time.
_RECEIVED_JS = """
({name, prop, since}) => {
  const out = [];
  const batches = window.__softplan.batches;
  for (let b = since; b < batches.length; b++) {
    for (const m of batches[b].messages) {
      if (m.name !== name) continue;
      const v = m.type === "SceneNodeUpdateMessage" ? (m.updates || {})[prop] : (m.props || {})[prop];
      if (v !== undefined) out.push([batches[b].t, ArrayBuffer.isView(v) ? Array.from(v) : v]);
    }
  }
  return out;
}
"""

# The page's drag, for timing: a second websocket sends the goal handle's update (msgpack, as
# viser's client does) and waits for the panel to show the next plan, then for two animation
# frames (the next frame drawn after the new arm arrived); the batch with the new arm is found
# among the recorded ones.
_DRAG_JS = """
async ({wsUrl, protocol, goals, timeoutMs, pauseMs}) => {
  const enc = new TextEncoder();
  function pack(v, out) {
    if (typeof v === "string") {
      const b = enc.encode(v);
      if (b.length < 32) out.push(0xa0 | b.length); else out.push(0xd9, b.length);
      for (const x of b) out.push(x);
    } else if (typeof v === "number") {
      const buf = new DataView(new ArrayBuffer(8)); buf.setFloat64(0, v);
      out.push(0xcb); for (let i = 0; i < 8; i++) out.push(buf.getUint8(i));
    } else if (Array.isArray(v)) {
      out.push(0x90 | v.length); for (const x of v) pack(x, out);
    } else {
      const keys = Object.keys(v); out.push(0x80 | keys.length);
      for (const k of keys) { pack(k, out); pack(v[k], out); }
    }
    return out;
  }
  const planNumber = () => {
    const m = document.body.textContent.match(/plan (\\d+)/);
    return m ? parseInt(m[1]) : -1;
  };
  const nextPlan = (before, t0) => new Promise((ok, fail) => {
    const check = () => {
      if (planNumber() > before) { observer.disconnect(); clearTimeout(timer); ok(performance.now()); }
    };
    const observer = new MutationObserver(check);
    observer.observe(document.body, {childList: true, subtree: true, characterData: true});
    const timer = setTimeout(() => { observer.disconnect(); fail(new Error("no new plan in time")); }, timeoutMs);
    check();
  });
  const ws = new WebSocket(wsUrl, [protocol]);
  ws.binaryType = "arraybuffer";
  await new Promise((ok, fail) => { ws.onopen = ok; ws.onerror = fail; });
  const out = [];
  for (const g of goals) {
    if (pauseMs > 0) await new Promise(r => setTimeout(r, pauseMs));
    const before = planNumber();
    const t0 = performance.now();
    ws.send(new Uint8Array(pack({type: "TransformControlsUpdateMessage", name: "/goal",
                                 wxyz: [1.0, 0.0, 0.0, 0.0], position: g, owner: ""}, [])));
    const shown = await nextPlan(before, t0);
    await new Promise(r => requestAnimationFrame(r));
    const first = performance.now();
    await new Promise(r => requestAnimationFrame(r));
    const second = performance.now();
    const arm = window.__softplan.batches.find(b => b.t >= t0 && b.messages.some(
      m => m.name === "/arm/segment_0" && m.type === "SceneNodeUpdateMessage"));
    out.push([arm ? arm.t - t0 : NaN, shown - t0, first - t0, second - t0]);
  }
  ws.close();
  return out;
}
"""


class HeadlessBrowser:
    """A headless Chromium with a fresh profile, looking at one page (a context manager).

    Args:
      executable: the Chromium to run (default :func:`find_chromium`).
      width, height: the window in pixels.

    Attributes:
      page: the Playwright page (its batches of viser messages recorded from the start).

    Raises:
      ImportError: Playwright is not installed. RuntimeError: no Chromium found, or it does not start.
    """

    def __init__(self, executable: str | None = None, width: int = 1200, height: int = 800):
        self.executable = executable or find_chromium()
        if self.executable is None:
            raise RuntimeError("no Chromium found (Debian: apt-get install chromium)")
        self.size = {"width": int(width), "height": int(height)}
        self._profile = None

    def __enter__(self):
        from playwright.sync_api import sync_playwright

        self._pw = sync_playwright().start()
        self._profile = tempfile.mkdtemp(prefix="softplan-chromium-")
        try:
            self.context = self._pw.chromium.launch_persistent_context(
                self._profile, executable_path=self.executable, headless=True, args=list(CHROMIUM_ARGS),
                viewport=self.size)
        except Exception as err:
            self.__exit__(None, None, None)
            raise RuntimeError(f"Chromium ({self.executable}) did not start: {err}") from None
        self.context.add_init_script(_RECORD_JS)
        self.page = self.context.pages[0] if self.context.pages else self.context.new_page()
        return self

    def __exit__(self, *exc):
        for closing in (getattr(self, "context", None), getattr(self, "_pw", None)):
            try:
                if closing is not None:
                    closing.close() if hasattr(closing, "close") else closing.stop()
            except Exception:  # noqa: BLE001 - closing down: nothing left to do about it
                pass
        if self._profile:
            shutil.rmtree(self._profile, ignore_errors=True)
        return False

    def open(self, url: str, timeout: float = 60.0) -> None:
        """Load the page and wait for its 3-D canvas."""
        self.page.goto(url, timeout=timeout * 1e3)
        self.page.wait_for_selector("canvas", timeout=timeout * 1e3)
        # The "software WebGL" notice (no GPU here) would cover part of every picture.
        self.page.add_style_tag(content=".mantine-Notifications-root { display: none !important; }")

    def batches(self) -> int:
        """How many batches of messages the page has received so far."""
        return int(self.page.evaluate("window.__softplan.batches.length"))

    def received(self, name: str, prop: str, since: int = 0) -> list:
        """The values scene node ``name`` received for ``prop`` (its creation or its updates),
        from batch ``since`` on, in order: arrays (a typed array flattened) or plain values."""
        got = self.page.evaluate(_RECEIVED_JS, {"name": name, "prop": prop, "since": int(since)})
        return [np.asarray(v) if isinstance(v, list) else v for _, v in got]

    def screenshot(self, path: str | None = None) -> np.ndarray:
        """The page as an (H, W, 3) uint8 image (also written to ``path`` as PNG if given)."""
        import io

        from PIL import Image

        png = self.page.screenshot(path=path)
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def drag(self, url: str, goals, pause: float = 0.0, timeout: float = 30.0) -> np.ndarray:
        """Drag the goal to each of ``goals`` (K, 3) over a websocket as the page does, each
        ``pause`` seconds after the last one's plan was drawn.

        Returns:
          (K, 4) seconds from each drag to: the batch of messages with the new arm handed to the
          page, the page's panel showing the new plan (its plan number), the next animation
          frame, and the one after it (by then the frame with the new arm has been drawn).
        """
        import viser

        ms = self.page.evaluate(_DRAG_JS, {"wsUrl": "ws" + url[len("http"):], "protocol": f"viser-v{viser.__version__}",
                                           "goals": np.asarray(goals, float).tolist(), "timeoutMs": timeout * 1e3,
                                           "pauseMs": pause * 1e3})
        return np.asarray(ms, np.float64) / 1e3
