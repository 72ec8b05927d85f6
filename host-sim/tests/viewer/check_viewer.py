#!/usr/bin/env python3
"""Drives a host-sim viewer page in a real browser (Debian's chromium, headless, through
Playwright): it loads with no console error and no network request; at two times the
vehicles on the page are the trace's, each drawn where the trace puts it, as long as the
car and along its heading, in its mode's colour (pixel checks on the canvas, with the view
set by the test, so a wrong world-to-screen transform, heading or colour fails); play
advances the time; hovering shows a vehicle's card. The opening view is readable: a
vehicle drawn at least MIN_PX long, the first vehicles on the canvas, the page saying how
to zoom and pan, and the legend naming A_S and A_C where there are junctions.

Usage: check_viewer.py PAGE.html TRACE.csv [SCREENSHOT.png [SCALE,X,Y[,FRACTION]]]
Exit 0 when every check holds; 1 with the first failure."""
import csv
import math
import shutil
import sys

from playwright.sync_api import sync_playwright

MODES = ["cruise", "lane_change", "yield", "waiting", "crossing", "fallback", "done"]
L, W = 4.5, 1.7
SCALE = 12.0  # px per m while checking one vehicle
MIN_PX = 20  # a vehicle's least length on the screen at the opening view


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


def close(a, b, tol=12):
    return all(abs(x - y) <= tol for x, y in zip(a, b))


def opening(page, rows, w, h):
    """The view the page opens at, before anything is touched."""
    scale, length = page.evaluate("[window.viewer.scale(), window.viewer.length]")
    if scale * length < MIN_PX:
        fail(f"opening view: a vehicle is {scale * length:.1f} px long ({scale:.2f} px/m), "
             f"under {MIN_PX} px")
    first = rows[min(rows)]
    on = 0
    for r in first.values():
        px, py = page.evaluate(f"window.viewer.toScreen({r['x']}, {r['y']})")
        on += 0 <= px <= w and 0 <= py <= h
    if on == 0:
        fail(f"opening view: none of the {len(first)} first vehicles is on the canvas")
    help_text = page.inner_text("#help")
    if "zoom" not in help_text or "drag" not in help_text:
        fail(f"the page does not say how to zoom and pan: {help_text!r}")
    legend = page.inner_text("#legend")
    if page.evaluate("window.viewer.junctions") and ("A_S" not in legend or "A_C" not in legend):
        fail(f"junctions on the page but the legend has no A_S and A_C: {legend!r}")
    print(f"opening view: {scale * length:.0f} px per vehicle, {on} of {len(first)} first "
          f"vehicles on the canvas; ", end="")


def main(page_path, trace_path, shot=None, view=None):
    rows = {}
    for r in csv.DictReader(open(trace_path)):
        rows.setdefault(round(float(r["t"]) * 100), {})[int(r["id"])] = r
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if not exe:
        fail("no chromium on PATH (Debian: apt-get install chromium)")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1200, "height": 800})
        errors, requests = [], []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.on("request", lambda q: requests.append(q.url)
                if not q.url.startswith(("file:", "data:", "blob:")) else None)
        page.goto("file://" + page_path)
        page.wait_for_function("window.viewer && window.viewer.ready", timeout=20000)
        end, dt = page.evaluate("[window.viewer.end, window.viewer.dt]")
        colours = page.evaluate("window.viewer.colours")
        w, h = page.evaluate("window.viewer.size()")
        opening(page, rows, w, h)
        checked = 0
        for frac in (0.3, 0.6):
            t = round(frac * end / dt) * dt
            key = round(t * 100)
            want = rows.get(key)
            if not want:
                fail(f"no trace rows at t = {t}")
            page.evaluate(f"window.viewer.pause(); window.viewer.seek({t})")
            got = {v["id"]: v for v in page.evaluate("window.viewer.vehicles()")}
            if set(got) != set(want):
                fail(f"t = {t}: the page shows {sorted(got)}, the trace has {sorted(want)}")
            for vid, r in sorted(want.items()):
                x, y, th = float(r["x"]), float(r["y"]), float(r["theta"])
                g = got[vid]
                if abs(g["x"] - x) > 0.011 or abs(g["y"] - y) > 0.011:
                    fail(f"t = {t}: vehicle {vid} at ({g['x']}, {g['y']}) on the page, ({x}, {y}) in the trace")
                # Alone within 10 m: its pixels are its own.
                if any(math.hypot(float(o["x"]) - x, float(o["y"]) - y) < 10
                       for oid, o in want.items() if oid != vid):
                    continue
                # The view centred 7 m east and 5 m north of it: on a screen with y down,
                # it must appear 7 m left of and 5 m below the centre.
                page.evaluate(f"window.viewer.setView({SCALE}, {x + 7}, {y + 5})")
                colour = [int(colours[MODES.index(r["mode"])][i:i + 2], 16) for i in (1, 3, 5)]
                cx, cy = w / 2 - 7 * SCALE, h / 2 + 5 * SCALE
                c, s = math.cos(th), math.sin(th)
                along = (cx + 0.3 * L * c * SCALE, cy - 0.3 * L * s * SCALE)
                beside = (cx - 1.4 * W * s * SCALE, cy - 1.4 * W * c * SCALE)
                points = [("centre", (cx, cy), True), ("along", along, True),
                          ("beside", beside, False)]
                # A long vehicle (a truck) is drawn as long as the trace says: 40 % of its
                # length ahead of its centre is still it, where a car would have ended.
                length = float(r.get("length") or L)
                if length > 2 * L:
                    far = (cx + 0.4 * length * c * SCALE, cy - 0.4 * length * s * SCALE)
                    points.append(("far along", far, True))
                for name, (px, py), inside in points:
                    pix = page.evaluate(f"window.viewer.pixel({px}, {py})")[:3]
                    if close(pix, colour) != inside:
                        fail(f"t = {t}: vehicle {vid} ({r['mode']}) {name} pixel {pix} "
                             f"{'is not' if inside else 'is'} its colour {colour}")
                checked += 1
        if checked < 2:
            fail(f"only {checked} vehicles could be checked alone")
        # Hover or click: the card.
        vid = next(iter(got))
        page.evaluate(f"window.viewer.select({vid})")
        card = page.evaluate("window.viewer.tip()")
        if f"vehicle {vid}" not in card or "speed" not in card or "mode" not in card:
            fail(f"no card for vehicle {vid}: {card!r}")
        page.evaluate("window.viewer.select(null)")
        page.click("#fit")
        # Play advances the time.
        page.evaluate("window.viewer.seek(0)")
        page.click("#play")
        page.wait_for_timeout(800)
        t1 = page.evaluate("window.viewer.time()")
        page.click("#play")
        if not t1 > 0.2:
            fail(f"play did not advance the time: {t1}")
        if shot:
            at = 0.3
            if view:  # "SCALE,X,Y[,FRACTION]": pixels per metre, the centre, when
                parts = [float(p) for p in view.split(",")]
                page.evaluate(f"window.viewer.setView({parts[0]}, {parts[1]}, {parts[2]})")
                at = parts[3] if len(parts) > 3 else at
            page.evaluate(f"window.viewer.seek({round(at * end / dt) * dt})")
            page.screenshot(path=shot, clip={"x": 0, "y": 0, "width": w, "height": 700})
        browser.close()
    if errors:
        fail(f"console errors: {errors}")
    if requests:
        fail(f"network requests: {requests}")
    print(f"viewer: {checked} vehicles drawn where the trace puts them (position, length, heading, "
          f"mode colour) at two times; play advanced to {t1:.2f} s; no console error, no request")
    return 0


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4, 5):
        print(__doc__)
        sys.exit(2)
    sys.exit(main(*sys.argv[1:]))
