"""Headless Chromium driven over the DevTools protocol (for the viewer's
end-to-end test and benchmark): Debian's ``chromium``, its WebGL2 on
SwiftShader (no GPU needed), commands over a WebSocket with aiohttp.

    async with Browser() as b:
        tab = await b.open(url)
        await tab.wait("window.oclgiState && oclgiState.ready")
        await tab.mouse("mousePressed", x, y)
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import os
import re
import shutil
import subprocess
import tempfile
import threading

import aiohttp

CHROMIUM = os.environ.get("OCLGI_CHROMIUM", "chromium")
COMMON = ["--headless=new", "--no-sandbox", "--no-first-run", "--no-default-browser-check",
          "--disable-background-timer-throttling", "--disable-renderer-backgrounding",
          "--disable-backgrounding-occluded-windows", "--window-size=1000,700"]
# What Chromium chooses by itself on a machine without a GPU: WebGL2 on
# SwiftShader (through ANGLE's Vulkan back end; current Chromium asks for
# the flag before it falls back to it), the page composited in software
# (SystemInfo.getInfo: gpu_compositing "disabled_software").
SOFTWARE = COMMON + ["--enable-unsafe-swiftshader"]
# Everything through SwiftShader, the compositor included (gpu_compositing
# "enabled"): about 14 ms more CPU a frame shown on 2 cores
# (bench/README.md, "Viewer"). The tests' browser.
SWIFTSHADER = SOFTWARE + ["--disable-gpu-sandbox", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]
FLAGS = SWIFTSHADER
CONFIGURATIONS = {"software": SOFTWARE, "swiftshader": SWIFTSHADER}


def chromium_path() -> str | None:
    return shutil.which(CHROMIUM)


class BrowserError(RuntimeError):
    pass


class Browser:
    def __init__(self, width: int = 1000, height: int = 700, flags: list[str] | None = None):
        self.size = (width, height)
        self.flags = FLAGS if flags is None else flags
        self.ids = itertools.count(1)
        self.waiting: dict[int, asyncio.Future] = {}

    async def __aenter__(self):
        exe = chromium_path()
        if exe is None:
            raise BrowserError(f"{CHROMIUM} is not installed (tools/ensure-chromium.sh installs Debian's)")
        self.profile = tempfile.mkdtemp(prefix="oclgi-chromium-")
        self.proc = subprocess.Popen([exe, *self.flags, f"--user-data-dir={self.profile}", "--remote-debugging-port=0",
                                      "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        loop = asyncio.get_running_loop()
        url = await asyncio.wait_for(loop.run_in_executor(None, self._devtools_url), 60)
        self.http = aiohttp.ClientSession()
        self.ws = await self.http.ws_connect(url, max_msg_size=0)
        self.reader = asyncio.create_task(self._read())
        return self

    def _devtools_url(self) -> str:
        for line in self.proc.stderr:
            m = re.search(r"DevTools listening on (ws://\S+)", line)
            if m:
                # keep draining stderr, or Chromium blocks on a full pipe
                threading.Thread(target=lambda: [None for _ in self.proc.stderr], daemon=True).start()
                return m.group(1)
        raise BrowserError(f"chromium ended without a DevTools address (status {self.proc.wait()})")

    async def __aexit__(self, *exc):
        try:
            await self.call("Browser.close")
        except Exception:
            pass
        self.reader.cancel()
        await self.http.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        shutil.rmtree(self.profile, ignore_errors=True)

    async def _read(self):
        async for msg in self.ws:
            data = json.loads(msg.data)
            fut = self.waiting.pop(data.get("id"), None)
            if fut is not None and not fut.done():
                if "error" in data:
                    fut.set_exception(BrowserError(f"{data['error']}"))
                else:
                    fut.set_result(data.get("result", {}))

    async def call(self, method: str, session: str | None = None, **params):
        i = next(self.ids)
        fut = asyncio.get_running_loop().create_future()
        self.waiting[i] = fut
        msg = {"id": i, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        await self.ws.send_str(json.dumps(msg))
        return await asyncio.wait_for(fut, 120)

    async def open(self, url: str) -> "Tab":
        target = (await self.call("Target.createTarget", url="about:blank"))["targetId"]
        session = (await self.call("Target.attachToTarget", targetId=target, flatten=True))["sessionId"]
        tab = Tab(self, target, session)
        await tab.call("Emulation.setDeviceMetricsOverride", width=self.size[0], height=self.size[1],
                       deviceScaleFactor=1, mobile=False)
        await tab.call("Page.navigate", url=url)
        return tab


class Tab:
    def __init__(self, browser: Browser, target: str, session: str):
        self.browser, self.target, self.session = browser, target, session

    async def call(self, method: str, **params):
        return await self.browser.call(method, self.session, **params)

    async def eval(self, expression: str):
        """The value of a JavaScript expression (awaited when a promise)."""
        r = await self.call("Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True)
        if "exceptionDetails" in r:
            raise BrowserError(f"{expression[:80]}: {r['exceptionDetails'].get('exception', {}).get('description')}")
        return r["result"].get("value")

    async def wait(self, expression: str, timeout: float = 120.0, every: float = 0.05):
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while True:
            value = await self.eval(f"(() => {{ try {{ return {expression}; }} catch (e) {{ return null; }} }})()")
            if value:
                return value
            if loop.time() > end:
                errors = await self.eval("window.oclgiState ? oclgiState.errors : null")
                raise BrowserError(f"timed out waiting for {expression} (page errors: {errors})")
            await asyncio.sleep(every)

    async def mouse(self, kind: str, x: float, y: float, button: str = "left"):
        """kind: mousePressed, mouseMoved, mouseReleased."""
        await self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button=button,
                        buttons=1 if kind != "mouseReleased" and button == "left" else 0, clickCount=1)

    async def screenshot(self, path) -> None:
        data = (await self.call("Page.captureScreenshot", format="png"))["data"]
        with open(path, "wb") as f:
            f.write(base64.b64decode(data))

    async def close(self) -> None:
        await self.browser.call("Target.closeTarget", targetId=self.target)
