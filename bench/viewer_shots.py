"""Screenshots of runs in the product's 3D viewer (the hub's viser scene), in headless Debian Chromium.

    .venv/bin/python bench/viewer_shots.py RUN_DIR [RUN_DIR ...] --out DIR

Each RUN_DIR is a `vtdslam run --out` folder (or a job's artifact folder); DIR/<name of RUN_DIR>.png is
written for each, after waiting `--wait` seconds for the software-rendered scene. For before/after pictures
of a change, e.g. the dense map with and without `dense.carve`. Prints the paths; asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--enable-unsafe-swiftshader"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--wait", type=float, default=25.0, help="seconds for the scene to render")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    args = ap.parse_args()

    from playwright.sync_api import sync_playwright

    from storage.artifacts import ArtifactStore
    from webui.viewer.hub import ViewerHub

    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        store = ArtifactStore(Path(tmp))
        (Path(tmp) / "artifacts").mkdir()
        for run in args.runs:  # the hub reads a job's artifacts: link each run in under its folder's name
            (Path(tmp) / "artifacts" / run.name).symlink_to(run.resolve())
        hub = ViewerHub(store)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=args.chromium, args=CHROMIUM_ARGS, headless=True)
                for run in args.runs:
                    srv = hub.open_run(run.name)
                    page = browser.new_page(viewport={"width": 1400, "height": 900})
                    page.goto(f"http://{srv.host}:{srv.port}/")
                    time.sleep(args.wait)
                    shot = args.out / f"{run.name}.png"
                    page.screenshot(path=str(shot))
                    page.close()
                    print(shot)
                browser.close()
        finally:
            hub.stop()


if __name__ == "__main__":
    main()
