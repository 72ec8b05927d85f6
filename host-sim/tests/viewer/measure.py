"""What a viewer page weighs and costs in Debian's chromium (headless, via playwright).

Usage: measure.py PAGE.html

Prints the file size, the time from navigation until the page is ready, and the mean
time to draw one frame (100 seeks spread over the run, each a full redraw).
"""
import os
import shutil
import sys
import time

from playwright.sync_api import sync_playwright


def main(page_path):
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if not exe:
        print("no chromium on PATH (Debian: apt-get install chromium)", file=sys.stderr)
        return 1
    size = os.path.getsize(page_path)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1200, "height": 800})
        t0 = time.perf_counter()
        page.goto("file://" + os.path.abspath(page_path))
        page.wait_for_function("window.viewer && window.viewer.ready", timeout=60000)
        load = time.perf_counter() - t0
        frame_ms = page.evaluate("""() => {
            const v = window.viewer, t0 = performance.now();
            for (let i = 0; i < 100; i++) v.seek(v.end * i / 100);
            return (performance.now() - t0) / 100;
        }""")
        vehicles = page.evaluate("window.viewer.vehicles().length")
        browser.close()
    print(f"{page_path}: {size / 1e6:.2f} MB, ready in {load:.2f} s, "
          f"{frame_ms:.2f} ms per frame ({vehicles} vehicles in the last frame drawn)")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__)
        sys.exit(2)
    sys.exit(main(sys.argv[1]))
