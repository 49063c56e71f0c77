"""The live page in a real headless Chromium (Debian's chromium driven by Playwright; nothing installed at run time)."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import pytest

pytest.importorskip("aiohttp")
sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install 'ax12emu[test]')")

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS  # noqa: E402
from emu_testkit import sdk_port  # noqa: E402

from ax12emu import VirtualBus  # noqa: E402

#: The system's Chromium (apt-get install chromium); Playwright's own download is never used.
CHROMIUM = Path("/usr/bin/chromium")
#: Flags for a quiet, offline, throwaway browser.
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    if not CHROMIUM.exists() and shutil.which("chromium") is None:
        pytest.skip("no Chromium at /usr/bin/chromium (apt-get install chromium)")
    with sync_api.sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(tmp_path_factory.mktemp("chromium-profile")),  # a fresh --user-data-dir
            executable_path=str(CHROMIUM if CHROMIUM.exists() else shutil.which("chromium")),
            headless=True,
            args=CHROMIUM_FLAGS,
        )
        try:
            yield context
        finally:
            context.close()


@pytest.fixture
def page(browser):
    page = browser.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    yield page
    page.close()
    assert not errors, f"the page's scripts failed: {errors}"


def open_view(page, bus) -> None:
    page.goto(bus.web_url)
    page.wait_for_function("Number(document.body.dataset.frames) >= 0", timeout=5000)


def test_a_card_for_every_servo(page):
    with VirtualBus([1, 3, 10], transport="inprocess", web=True) as bus:
        open_view(page, bus)
        for servo_id in (1, 3, 10):
            card = page.locator(f"#servo-{servo_id}")
            card.wait_for(timeout=5000)
            assert f"ID {servo_id}" in card.locator(".name").inner_text()
            assert "AX-12A · protocol 1.0" in card.locator(".model").inner_text()
        assert page.locator(".card").count() == 3


def test_a_goal_written_through_the_sdk_moves_the_dial_and_the_plot_within_a_second(page):
    with VirtualBus([1], transport="tcp", web=True) as bus:
        open_view(page, bus)
        page.wait_for_function("document.querySelector('#servo-1 .dial')?.dataset.present === '512'", timeout=5000)
        dial_before = page.eval_on_selector("#servo-1 .dial", "canvas => canvas.toDataURL()")
        with sdk_port(bus.port) as (port, ph):
            assert ph.write1ByteTxRx(port, 1, 24, 1) == (COMM_SUCCESS, 0)  # Torque Enable
            assert ph.write2ByteTxRx(port, 1, 30, 800) == (COMM_SUCCESS, 0)  # Goal Position
            written = time.monotonic()
        page.wait_for_function(
            """() => {
                const dial = document.querySelector('#servo-1 .dial');
                const plot = document.querySelector('#servo-1 .plot[data-kind=position]');
                const last = JSON.parse(plot.dataset.last || '{}');
                return dial.dataset.goal === '800' && Number(dial.dataset.present) > 520 && last.goal === 800 && last.pos > 520;
            }""",
            timeout=1000,
        )
        assert time.monotonic() - written < 1.5  # the wait above allows 1 s; this bounds the whole round trip
        assert page.eval_on_selector("#servo-1 .dial", "canvas => canvas.toDataURL()") != dial_before
        assert "→ 800" in page.locator("#servo-1 .fields").inner_text()


def test_a_fault_toggled_in_the_page_is_a_timeout_in_the_sdk(page):
    with VirtualBus([1, 2], transport="tcp", web=True) as bus, sdk_port(bus.port) as (port, ph):
        open_view(page, bus)
        page.locator("#servo-1").wait_for(timeout=5000)
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
        page.click("#servo-1 button[data-act=vanish]")
        page.wait_for_function("document.getElementById('message').textContent === 'servo 1 vanished'", timeout=3000)
        assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT
        assert ph.ping(port, 2)[1] == COMM_SUCCESS
        page.wait_for_function("document.querySelector('#servo-1 .faults').textContent.includes('vanished')", timeout=3000)
        page.click("#servo-1 button[data-act=reappear]")
        page.wait_for_function("document.getElementById('message').textContent === 'servo 1 back'", timeout=3000)
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
        page.fill("#drop", "1")
        page.click("#apply-reply-faults")
        page.wait_for_function("document.getElementById('message').textContent.startsWith('reply faults: drop 1')", timeout=3000)
        assert ph.ping(port, 2)[1] == COMM_RX_TIMEOUT
        page.click("#clear-faults")
        page.wait_for_function("document.getElementById('message').textContent === 'every fault lifted'", timeout=3000)
        assert ph.ping(port, 2)[1] == COMM_SUCCESS
        # Every change is in the packet log, beside the SDK's packets; the ID filter keeps servo 2's.
        page.wait_for_function("document.getElementById('log').textContent.includes('servo 1 vanished')", timeout=3000)
        page.fill("#filter-id", "2")
        page.wait_for_function(
            """() => { const rows = [...document.querySelectorAll('#log div')];
                       return rows.length > 0 && rows.every(r => r.textContent.includes('id=2') || r.textContent.includes('ID 2')); }""",
            timeout=3000,
        )


def test_a_bad_request_gets_a_clear_error_and_the_bus_keeps_running(page):
    with VirtualBus([1], transport="tcp", web=True) as bus:
        open_view(page, bus)
        page.locator("#servo-1").wait_for(timeout=5000)
        answer = page.evaluate(
            """async () => { const r = await fetch('/api/control', {method: 'POST', headers: {'Content-Type': 'application/json'},
                                                                  body: '{"action": 12'});
                             return [r.status, await r.json()]; }"""
        )
        assert answer[0] == 400 and "not JSON" in answer[1]["error"]
        frames = int(page.evaluate("document.body.dataset.frames"))
        page.wait_for_function(f"Number(document.body.dataset.frames) > {frames + 5}", timeout=2000)  # still streaming
        with sdk_port(bus.port) as (port, ph):
            assert ph.ping(port, 1)[1] == COMM_SUCCESS


def test_x_series_cards_on_a_mixed_wire_show_units_and_take_their_own_alarms(page):
    """AX-12A and XL430 both with ID 1: one card each; the XL430's alarm names are Hardware Error Status bits."""
    from ax12emu.live import ByteTap, LiveView, ServedControls
    from ax12emu.live.buses import decoder_options

    with VirtualBus(servo="1:ax-12a,1:xl430-w250", transport="inprocess", virtual_time=True, baud_bps=1_000_000) as bus:
        tap = ByteTap(bus._link.trace)
        bus._link.trace = tap
        with LiveView(bus.call, controls=ServedControls(bus.call), tap=tap, web=("127.0.0.1", 0), **bus.call(decoder_options)) as view:
            page.goto(view.url)
            x_card = page.locator("#servo-1-p20")
            x_card.wait_for(timeout=5000)
            assert page.locator("#servo-1-p10").count() == 1 and page.locator(".card").count() == 2
            assert "XL430-W250 · protocol 2.0" in x_card.locator(".model").inner_text()
            page.wait_for_function("document.querySelector('#servo-1-p20 .dial')?.dataset.present === '2048'", timeout=5000)
            fields = x_card.locator(".fields").inner_text()
            assert "2048 (180.0°)" in fields and "rpm" in fields and "11.1 V" in fields and "position 0..4095" in fields
            assert "1,000,000 bps (3)" in fields  # the rate it listens at, and its Baud Rate register
            # The dial as the degrees: 4096 counts a turn (e-manual X series), so 1024 is a quarter of it.
            dial = next(servo["dial"] for servo in view.sampler.latest["servos"] if servo["protocol"] == "2.0")
            quarter_deg = page.evaluate("(dial) => (dialAngle(1024, dial) - dialAngle(0, dial)) * 180 / Math.PI", dial)
            assert quarter_deg == pytest.approx(90.0)
            x_card.locator("select[data-field=alarm]").select_option("electrical_shock")
            x_card.locator("button[data-act=alarm]").click()
            page.wait_for_function(
                "document.getElementById('message').textContent === 'servo 1: alarm electrical_shock forced (Protocol 2.0)'", timeout=3000
            )
            page.wait_for_function(
                "[...document.querySelectorAll('#servo-1-p20 .bits span.set')].map(s => s.textContent).join() === 'electrical_shock'", timeout=3000
            )
            assert bus.read(1, "hardware_error_status", protocol=2.0) == 0x10
            assert page.locator("#servo-1-p10 .bits span.set").count() == 0
