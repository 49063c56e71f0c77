"""Screenshots of the live view from a real run: the web page and the terminal monitor.

Starts ``ax12emu serve --ids 1,2,3 --web ... --monitor`` inside a detached
tmux session (a real terminal for the monitor), drives the servos through
dynamixel-sdk on the pty (goals, a wheel-mode servo, a held temperature, a
polling loop so the packet log and the plots have something to show), then

* photographs the page in headless Chromium (Debian's ``/usr/bin/chromium``
  driven by Playwright; nothing downloaded) -> ``tools/figures/live_view.png``;
* captures the tmux pane with its colours (``tmux capture-pane -e``), turns it
  into an SVG with rich and photographs that -> ``tools/figures/live_monitor.png``.

Both PNGs are reduced to a small palette so they stay small in the repository.

Usage: ``python tools/screenshots.py [--out tools/figures]`` (needs tmux, chromium, playwright, the web extra).
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

from dynamixel_sdk import PacketHandler, PortHandler

from ax12emu.cli.arg_types import OneLineParser, positive_float

ROOT = Path(__file__).resolve().parent.parent
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]
SESSION = "ax12emu-screenshots"
PANE_COLUMNS, PANE_ROWS = 150, 12


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def wait_for(predicate, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            value = predicate()
        except OSError:
            value = None
        if value:
            return value
        time.sleep(0.1)
    raise RuntimeError(f"timed out waiting for {what}")


def post(url: str, message: dict) -> None:
    request = urllib.request.Request(url + "api/control", data=json.dumps(message).encode(), method="POST",
                                     headers={"Content-Type": "application/json"})  # as the page sends them
    with urllib.request.urlopen(request, timeout=5) as answer:
        answer.read()


def drive(port_path: str, url: str, seconds: float) -> None:
    """Move the servos and poll them, as a robot program would, for ``seconds``."""
    port, ph = PortHandler(port_path), PacketHandler(1.0)
    port.openPort()
    port.setBaudRate(1_000_000)
    try:
        ph.write1ByteTxRx(port, 1, 24, 1)
        ph.write2ByteTxRx(port, 1, 32, 200)
        ph.write2ByteTxRx(port, 1, 30, 820)
        ph.write1ByteTxRx(port, 2, 24, 1)
        ph.write4ByteTxRx(port, 2, 6, 0)  # both angle limits 0: wheel mode
        time.sleep(0.1)  # an AX-12 ignores packets for a few ms after an EEPROM write
        ph.write2ByteTxRx(port, 2, 32, 1024 + 400)  # turning CW
        ph.write1ByteTxRx(port, 3, 25, 1)  # LED on
        post(url, {"action": "temperature", "id": 3, "celsius": 78})  # over the 70 C limit: Overheating
        end = time.monotonic() + seconds
        flipped = False
        while time.monotonic() < end:
            for servo_id in (1, 2, 3):
                ph.read2ByteTxRx(port, servo_id, 36)
            if not flipped and time.monotonic() > end - seconds / 2:
                ph.write2ByteTxRx(port, 1, 30, 300)
                flipped = True
            time.sleep(0.01)
    finally:
        port.closePort()


def small_png(path: Path, colours: int = 64) -> None:
    """Reduce a screenshot to a palette (a few tens of kB instead of hundreds)."""
    from PIL import Image

    with Image.open(path) as image:
        reduced = image.convert("RGB").quantize(colors=colours)
    reduced.save(path, optimize=True)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "tools" / "figures", help="where the PNGs go")
    parser.add_argument("--seconds", type=positive_float, default=6.0,
                        help="how long the servos are driven before the pictures")
    args = parser.parse_args(argv)
    for tool in ("tmux", CHROMIUM):
        if shutil.which(tool) is None:
            parser.error(f"{tool} is needed (apt-get install tmux chromium)")
    from playwright.sync_api import sync_playwright
    from rich.console import Console
    from rich.text import Text

    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file of that name, or no permission: said before tmux and the browser start
        parser.exit(2, f"{parser.prog}: error: --out: {exc}\n")
    with tempfile.TemporaryDirectory() as tmp:
        link = Path(tmp, "ax12")
        web_port = free_port()
        url = f"http://127.0.0.1:{web_port}/"
        command = [sys.executable, "-m", "ax12emu", "serve", "--ids", "1,2,3", "--link", str(link),
                   "--web", f"127.0.0.1:{web_port}", "--monitor"]
        subprocess.run(["tmux", "new-session", "-d", "-s", SESSION, "-x", str(PANE_COLUMNS), "-y", str(PANE_ROWS),
                        subprocess.list2cmdline(command) + " 2>&1"], check=True, cwd=ROOT)
        try:
            wait_for(link.exists, 20, "the emulator's pty")
            wait_for(lambda: urllib.request.urlopen(url + "api/servos", timeout=2).status == 200, 20, "the live page")
            with sync_playwright() as playwright:
                context = playwright.chromium.launch_persistent_context(
                    str(Path(tmp, "profile")), executable_path=CHROMIUM, headless=True, args=CHROMIUM_FLAGS,
                    viewport={"width": 1400, "height": 1000},
                )
                try:
                    page = context.new_page()
                    page.goto(url)
                    # The pictures are taken while the servos are still driven, so the rates are live.
                    driver = threading.Thread(target=drive, args=(str(link), url, args.seconds + 4))
                    driver.start()
                    page.select_option("#window-s", "10")
                    page.wait_for_timeout(args.seconds * 1000)
                    page_png = args.out / "live_view.png"
                    page.screenshot(path=str(page_png), full_page=True)
                    small_png(page_png)
                    pane = subprocess.run(["tmux", "capture-pane", "-p", "-e", "-t", SESSION], capture_output=True, text=True, check=True).stdout
                    console = Console(record=True, width=PANE_COLUMNS, file=open("/dev/null", "w"), force_terminal=True)
                    console.print(Text.from_ansi(pane.rstrip("\n")))
                    svg = Path(tmp, "monitor.svg")
                    svg.write_text(console.export_svg(title="ax12emu serve --monitor"))
                    driver.join()
                    page.goto(svg.as_uri())
                    page.evaluate("() => { const svg = document.querySelector('svg'); svg.setAttribute('width', svg.viewBox.baseVal.width); svg.setAttribute('height', svg.viewBox.baseVal.height); }")
                    monitor_png = args.out / "live_monitor.png"
                    page.locator("svg").screenshot(path=str(monitor_png))
                    small_png(monitor_png)
                finally:
                    context.close()
        finally:
            subprocess.run(["tmux", "kill-session", "-t", SESSION], check=False)
    for name in ("live_view.png", "live_monitor.png"):
        print(f"{args.out / name}: {(args.out / name).stat().st_size // 1024} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
