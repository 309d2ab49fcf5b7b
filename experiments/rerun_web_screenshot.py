"""Does an episode's .rrd open and draw in the Rerun web viewer? A headless screenshot.

No display is needed: the `rerun` CLI (rerun-sdk) hosts its web viewer on 127.0.0.1, the episode's
folder is served on 127.0.0.1 (with the CORS header the viewer's fetch needs), and a headless
Chromium with the SwiftShader software rasteriser opens the viewer on the file; after `--wait`
seconds the page is captured over the Chrome DevTools protocol.

    pip install websocket-client      # the DevTools client; not a hexbench dependency
    python experiments/rerun_web_screenshot.py runs/x/episodes/stairs-5cm-00.rrd --out docs/img/rerun-stairs-episode.png

Needs `chromium` on PATH (`make browser` installs Debian's).
"""

from __future__ import annotations

import argparse
import base64
import functools
import http.server
import json
import shutil
import subprocess
import threading
import time
import urllib.request
from pathlib import Path

VIEWER_PORT, GRPC_PORT, FILES_PORT, DEVTOOLS_PORT = 9090, 9876, 8765, 9333


class _CorsHandler(http.server.SimpleHTTPRequestHandler):
    def end_headers(self):
        self.send_header("Access-Control-Allow-Origin", "*")
        super().end_headers()

    def log_message(self, *args):  # quiet
        pass


def _wait_http(url: str, timeout_s: float = 30.0):
    end = time.monotonic() + timeout_s
    while True:
        try:
            return urllib.request.urlopen(url, timeout=2)
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rrd", type=Path)
    parser.add_argument("--out", type=Path, required=True, help="PNG to write")
    parser.add_argument("--wait", type=float, default=90.0, help="seconds to let the viewer load and draw")
    args = parser.parse_args()
    import websocket  # websocket-client

    rrd = args.rrd.resolve()
    files = http.server.ThreadingHTTPServer(("127.0.0.1", FILES_PORT),
                                            functools.partial(_CorsHandler, directory=str(rrd.parent)))
    threading.Thread(target=files.serve_forever, daemon=True).start()
    viewer = subprocess.Popen([shutil.which("rerun") or "rerun", "--web-viewer", "--bind", "127.0.0.1",
                               "--web-viewer-port", str(VIEWER_PORT), "--port", str(GRPC_PORT), "--renderer", "webgl"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    browser = subprocess.Popen(["chromium", "--headless=new", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
                                "--enable-unsafe-swiftshader", "--window-size=1400,850",
                                f"--remote-debugging-port={DEVTOOLS_PORT}", "--remote-allow-origins=*", "about:blank"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_http(f"http://127.0.0.1:{VIEWER_PORT}/")
        tabs = json.load(_wait_http(f"http://127.0.0.1:{DEVTOOLS_PORT}/json"))
        ws = websocket.create_connection(next(t for t in tabs if t["type"] == "page")["webSocketDebuggerUrl"])
        counter = iter(range(1, 1_000_000))

        def call(method: str, **params) -> dict:
            msg_id = next(counter)
            ws.send(json.dumps({"id": msg_id, "method": method, "params": params}))
            while True:
                msg = json.loads(ws.recv())
                if msg.get("id") == msg_id:
                    return msg

        call("Emulation.setDeviceMetricsOverride", width=1400, height=850, deviceScaleFactor=1, mobile=False)
        file_url = f"http://127.0.0.1:{FILES_PORT}/{rrd.name}"
        call("Page.navigate", url=f"http://127.0.0.1:{VIEWER_PORT}/?url={file_url}&renderer=webgl")
        time.sleep(args.wait)
        shot = call("Page.captureScreenshot", format="png")
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_suffix(".png.tmp")
        tmp.write_bytes(base64.b64decode(shot["result"]["data"]))
        tmp.replace(args.out)
        print(f"wrote {args.out}")
    finally:
        browser.kill()
        viewer.kill()
        files.shutdown()


if __name__ == "__main__":
    main()
