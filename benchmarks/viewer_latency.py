"""How long a person waits in ``stmpl view``: from a pointer event in the browser to the updated
surface on screen, in Debian's chromium driven headless by Playwright (software WebGL).

    python benchmarks/viewer_latency.py [--model zoo:gnn_arm_bodies] [--places 24]
        [--shots docs]

The viewer serves the fine left arm with the model at fidelity auto; the browser clicks the
front of the arm at ``--places`` places along it, twice: the first pass meets each place new
(a model on the linear FEM prior needs that place's columns then: Naive answers at once as its
stand-in while they are solved, and the model's own answer follows), the second finds them
cached. Each latency runs from just before the click is dispatched to the second animation
frame after the page shows the new answer (the answer's stamp in the page; the surface tiles
arrive in the same message batch, before it). Then a drag along the arm: each pointer move to
the next answer shown (viser sends drag updates at most about 20 times a second). Then each
place clicked twice more: the second answer redraws no tile, which leaves the page's own share
(the event's round trip, the page's text, two frames). Prints the median and 95th percentile of
each, and the server's own share (event received to tiles sent). ``--prepare``: the viewer
solves the body's linear FEM columns before it serves (the first touch then waits for none).
``--shots``: also write the docs' screenshots (``viewer.png``, ``viewer_outside.png``) there.
"""

from __future__ import annotations

import argparse
import shutil
import socket
import time
from pathlib import Path

import numpy as np

from stmpl.machine import describe
from stmpl.viewer.app import Viewer, project

ARGS = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader"]
W, H = 1280, 800
"""The page's default size, px."""
STAND_IN = "zoo:naive_arm_fine"
"""The model that answers at once where the measured one waits for its prior's columns."""


def facing(part, along: float) -> int:
    """The vertex at fraction ``along`` the arm that faces the camera most (lowest y)."""
    s = part.axial
    ring = np.flatnonzero(np.abs(s - s.min() - along * np.ptp(s)) < 0.005)
    return int(ring[np.argmin(part.vertices[ring, 1])])


def shown(page) -> int:
    """How many answers the page has shown."""
    return int(page.locator("#stmpl-answer").get_attribute("data-n") or 0)


def wait_shown(page, n: int, timeout: float = 120.0) -> None:
    """Until the page shows answer ``n``, then two animation frames (the frame that draws it)."""
    page.wait_for_function(
        f"(document.getElementById('stmpl-answer')?.dataset.n | 0) >= {n}",
        timeout=timeout * 1e3,
        polling=2,  # ms
    )
    page.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


def stats(x: list) -> str:
    a = 1e3 * np.asarray(x)
    return f"median {np.median(a):.1f} ms, p95 {np.percentile(a, 95):.1f} ms (n = {len(a)})"


def main(argv=None) -> None:
    from playwright.sync_api import sync_playwright  # deferred: the benchmark's browser

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="zoo:gnn_arm_bodies")
    ap.add_argument("--places", type=int, default=24)
    ap.add_argument("--shots", type=Path, help="folder for the docs' screenshots")
    ap.add_argument(
        "--prepare", action="store_true", help="the viewer prepares the body first (--prepare)"
    )
    ap.add_argument(
        "--viewport",
        nargs=2,
        type=int,
        default=[W, H],
        metavar=("WIDTH", "HEIGHT"),
        help="the page's size in pixels (software WebGL draws every one of them)",
    )
    args = ap.parse_args(argv)
    w, h = args.viewport
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("chromium is not installed: apt install chromium")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.perf_counter()
    # Naive beside the model, as `stmpl view` serves it: at a place new to the model's prior it
    # answers at once, marked as a stand-in, while the prior's columns are solved
    viewer = Viewer([args.model, STAND_IN], port=port, prepare=args.prepare)
    viewer.mailbox.idle(600)
    print(
        f"{describe()}; viewer up with {args.model} (auto) in {time.perf_counter() - t0:.1f} s; "
        f"page {w} x {h} px"
    )
    part = viewer.part
    places = [facing(part, f) for f in np.linspace(0.15, 0.85, args.places)]
    out: dict = {"first": [], "cached": [], "same": [], "drag": []}
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=ARGS)
            page = browser.new_page(viewport={"width": w, "height": h})
            page.goto(f"http://127.0.0.1:{port}")
            page.wait_for_selector("#stmpl-answer", timeout=120_000)
            time.sleep(2.0)
            camera = next(iter(viewer.server.get_clients().values())).camera
            for name in ("first", "cached"):
                for v in places:
                    n = shown(page)
                    x, y = project(camera, part.vertices[v], w, h)
                    t = time.perf_counter()
                    page.mouse.click(x, y)
                    wait_shown(page, n + 1)
                    out[name].append(time.perf_counter() - t)
            server = list(viewer.latencies[-len(places) :])
            sent_before = viewer.tiles_sent
            for v in places:  # the place just pressed again: an answer with nothing to redraw
                x, y = project(camera, part.vertices[v], w, h)
                n = shown(page)
                page.mouse.click(x, y)
                wait_shown(page, n + 1)
                n = shown(page)
                t = time.perf_counter()
                page.mouse.click(x, y)
                wait_shown(page, n + 1)
                out["same"].append(time.perf_counter() - t)
            redrawn = viewer.tiles_sent - sent_before
            a, b = (
                project(camera, part.vertices[places[0]], w, h),
                project(camera, part.vertices[places[-1]], w, h),
            )
            page.mouse.move(*a)
            page.mouse.down()
            for k in range(1, 41):
                n = shown(page)
                t = time.perf_counter()
                page.mouse.move(a[0] + (b[0] - a[0]) * k / 40, a[1] + (b[1] - a[1]) * k / 40)
                try:
                    wait_shown(page, n + 1, timeout=2.0)
                    out["drag"].append(time.perf_counter() - t)
                except Exception:  # no drag update for this move (throttled): not an answer
                    pass
            page.mouse.up()
            if args.shots:
                args.shots.mkdir(parents=True, exist_ok=True)
                close = page.locator("button.mantine-Notification-closeButton")
                for k in range(close.count()):  # the headless browser's software-WebGL note
                    close.nth(k).click()
                x, y = project(camera, part.vertices[facing(part, 0.45)], w, h)
                n = shown(page)
                page.mouse.click(x, y)
                wait_shown(page, n + 1)
                page.mouse.move(40, h - 40)  # no hover outline on the skin
                time.sleep(1.0)
                page.screenshot(path=str(args.shots / "viewer.png"))
                force = page.locator(
                    "xpath=//*[normalize-space(text())='force, N']/ancestor::div"
                    "[.//input[@type='text']][1]//input[@type='text']"
                )
                n = shown(page)
                force.fill("3")
                force.press("Enter")
                wait_shown(page, n + 1)
                time.sleep(1.0)
                page.screenshot(path=str(args.shots / "viewer_outside.png"))
            browser.close()
    finally:
        viewer.close()
    print(f"click at a new place (first touch): {stats(out['first'])}")
    print(f"click at a place seen before:       {stats(out['cached'])}")
    print(f"  of which the server (event to tiles sent): {stats(server)}")
    print(f"click again where it pressed (no tile): {stats(out['same'])}")
    print(f"  tiles sent over those {2 * len(places)} clicks: {redrawn}")
    if out["drag"]:
        print(f"drag, pointer move to answer shown:  {stats(out['drag'])}")
    print(f"answers dropped while busy: {viewer.mailbox.dropped}")


if __name__ == "__main__":
    main()
