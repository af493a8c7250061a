"""Refresh the README's pictures in docs/pictures/: what the product looks like.

    PYTHONPATH=. python docs/make_pictures.py [--out docs/pictures] [--bonn ../shared/data/bonn_crowd_dev]

1. The service (`vtdslam serve`: api, worker, viewer) on free ports and a temp data dir, as the browser tests
   start it (tests/e2e/services.py); a generated sequence (`vtdslam synth`, 60 frames, one walker) uploaded
   through the REST api, a `full` job run on it; headless Chromium (Playwright, as the browser tests) takes the
   dashboard, the job page and the 3D viewer.
2. A `full` run on a generated room with two walkers (`vtdslam synth`, 120 frames): input, mask and restored
   background of the frame restoration changed most (`restored_frame.jpg`).
3. A `full` run (`vtdslam run`) on 120 frames of real footage with people walking, the Bonn RGB-D Dynamic "crowd"
   sequence (`$VTD_SHARED_DIR/data/bonn_crowd_dev`; skipped when absent): the run's figure of x/y/z against
   ground truth (`trajectory_xyz.png`), and its restored frame in `local/` (git-ignored: nothing of the shared
   data is ever committed, so the README shows the generated room's restoration instead).

Every picture is downscaled to at most WIDTH pixels wide. Needs Playwright's Python package and Chromium
(`/usr/bin/chromium`, or `$VTD_TEST_CHROMIUM`); takes a few minutes of CPU.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import cv2
import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from formats import artifacts  # noqa: E402
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS  # noqa: E402
from tests.e2e.services import ServiceProcesses  # noqa: E402

WIDTH = 900
JOB_TIMEOUT_S = 900
VIEWER_WAIT_S = 15  # SwiftShader renders WebGL at a few frames per second
LOCAL = "local"  # pictures of shared data: made for a look, git-ignored, never committed
BONN_START, BONN_FRAMES = 190, 120  # people walk through these frames (the first ~75 show an empty room)


def clean_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if not k.startswith("VTD_") or k.startswith("VTD_TEST_")}


def cli(*args: str, env: dict[str, str] | None = None) -> None:
    subprocess.run([sys.executable, "-m", "cli.main", *args], cwd=ROOT, env=env, check=True, timeout=1800)


def read(path: Path) -> np.ndarray:
    img = cv2.imread(str(path))
    if img is None:
        raise OSError(f"could not read {path}")
    return img


def decode(png: bytes) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise OSError("could not decode a screenshot")
    return img


def save(img: np.ndarray, path: Path, quality: int = 85) -> Path:
    """``img`` (BGR) downscaled to at most WIDTH wide, PNG or JPEG by ``path``'s suffix."""
    if img.shape[1] > WIDTH:
        img = cv2.resize(img, (WIDTH, round(img.shape[0] * WIDTH / img.shape[1])), interpolation=cv2.INTER_AREA)
    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if path.suffix == ".jpg" else [cv2.IMWRITE_PNG_COMPRESSION, 9]
    if not cv2.imwrite(str(path), img, params):
        raise OSError(f"could not write {path}")
    print(f"  {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: {img.shape[1]}x{img.shape[0]}, "
          f"{path.stat().st_size // 1024} KiB")
    return path


def save_png_bytes(data: bytes, path: Path) -> Path:
    return save(decode(data), path)


def synth_archive(tmp: Path) -> Path:
    seq = tmp / "synth_walk60"
    cli("synth", str(seq), "--frames", "60", "--people", "1", env=clean_env())
    out = tmp / "synth_walk60.zip"
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as zf:
        for path in sorted(seq.rglob("*")):
            if path.is_file():
                zf.write(path, Path("synth_walk60") / path.relative_to(seq))
    return out


def service_pictures(tmp: Path, out: Path) -> None:
    from playwright.sync_api import sync_playwright

    archive = synth_archive(tmp)
    with ServiceProcesses(tmp) as svc:
        svc.spawn("-m", "cli.main", "serve")
        svc.wait_until("the api", svc.healthy(f"{svc.base}/api/v1/health"))
        svc.wait_until("the viewer hub", svc.healthy(f"http://127.0.0.1:{svc.viewer_port}/health"))
        api = f"{svc.base}/api/v1"
        with archive.open("rb") as fh:
            r = httpx.post(f"{api}/sequences", files={"file": (archive.name, fh, "application/zip")},
                           data={"camera": "tum3"}, timeout=300)
        r.raise_for_status()
        seq_id = r.json()["id"]
        for preset in ("orb-only", "full"):  # two runs, so the dashboard lists more than one
            r = httpx.post(f"{api}/jobs", json={"sequence_id": seq_id, "preset": preset}, timeout=30)
            r.raise_for_status()
            job_id = r.json()["id"]
            deadline = time.monotonic() + JOB_TIMEOUT_S
            while (status := httpx.get(f"{api}/jobs/{job_id}", timeout=30).json()["status"]) not in (
                    "succeeded", "failed", "cancelled"):
                if time.monotonic() > deadline:
                    raise TimeoutError(f"job {job_id} ({preset}) did not finish\n" + svc.tail())
                time.sleep(2)
            if status != "succeeded":
                raise RuntimeError(f"job {job_id} ({preset}) {status}\n" + svc.tail())
            print(f"  job {job_id} ({preset}) succeeded")
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_context(viewport={"width": 1280, "height": 900}, base_url=svc.base).new_page()
            page.set_default_timeout(60_000)
            page.goto("/")
            page.wait_for_function("() => !/Loading/.test(document.body.innerText)")
            time.sleep(1)
            save_png_bytes(page.screenshot(), out / "dashboard.png")
            page.goto(f"/jobs/{job_id}")
            page.locator("#plot-traj svg path.series").first.wait_for()
            page.evaluate("() => document.querySelectorAll('img').forEach(i => { i.loading = 'eager'; })")
            page.wait_for_function("() => [...document.querySelectorAll('img')].every(i => i.complete)")
            time.sleep(1)
            save(job_page(page), out / "job_page.png")
            page.click("#viewer-btn")
            page.wait_for_function("() => document.getElementById('viewer').src.startsWith('http')")
            page.frame_locator("#viewer").locator("canvas").first.wait_for(state="attached")
            time.sleep(VIEWER_WAIT_S)
            viewer = page.frame_locator("#viewer")
            for close in viewer.locator(".mantine-Notification-closeButton, [class*=Notification] button").all():
                try:  # viser's "software WebGL rendering" notice (headless Chromium has no GPU)
                    close.click(timeout=2000)
                except Exception as exc:  # noqa: BLE001 - a notice left on screen spoils nothing but the look
                    print(f"  could not close a viewer notice: {exc}")
            time.sleep(1)
            page.locator("#viewer-wrap").scroll_into_view_if_needed()
            img = decode(page.locator("#viewer-wrap").screenshot())
            save(img, out / "viewer.jpg")
            browser.close()


def job_page(page) -> np.ndarray:  # noqa: ANN001 (a Playwright page)
    """The job page without its long tables: from the top to the end of the first metrics table, then from the
    plots to the end of the frame previews (the whole page when those parts are not found)."""
    img = decode(page.screenshot(full_page=True))
    spans = page.evaluate("""(sels) => sels.map((s) => { const e = document.querySelector(s);
        if (!e || e.hidden) return null; const r = e.getBoundingClientRect();
        return [r.top + window.scrollY, r.bottom + window.scrollY]; })""",
                          ["#metrics-table", "section.plots", "#previews-card"])
    if any(span is None for span in spans):
        return img
    (_, head_end), (body_top, _), (_, body_end) = spans
    cut = np.full((6, img.shape[1], 3), 200, np.uint8)  # a grey line where the tables were left out
    return np.vstack([img[: round(head_end) + 12], cut, img[round(body_top) - 12: round(body_end) + 12]])


def restored_picture(run: Path, dest: Path) -> None:
    """Input | mask | restored of the frame restoration changed most in `run`'s previews (one frame)."""
    shown = [parsed[0] for p in run.glob("frame_*_restored.jpg") if (parsed := artifacts.parse_frame_image(p.name))]
    if not shown:
        raise RuntimeError(f"the run in {run} wrote no restored preview")

    def changed(index: int) -> float:
        rgb, restored = (read(run / artifacts.frame_image(index, k)) for k in ("rgb", "restored"))
        return float(np.abs(rgb.astype(np.int16) - restored).mean())

    index = max(sorted(shown), key=changed)
    before, mask, after = (read(run / artifacts.frame_image(index, k)) for k in ("rgb", "mask", "restored"))
    gap = np.full((before.shape[0], 8, 3), 255, np.uint8)
    save(np.hstack([before, gap, mask, gap, after]), dest, quality=80)


def synth_pictures(tmp: Path, out: Path) -> None:
    """A `full` run on a generated room with two walkers: its restored frame (committed: all ours)."""
    seq, run = tmp / "synth_room", tmp / "synth_full"
    cli("synth", str(seq), "--frames", "120", "--people", "2", env=clean_env())
    cli("run", str(seq), "--out", str(run), "--preset", "full", "--camera", "tum3", "--quiet")
    restored_picture(run, out / "restored_frame.jpg")


def bonn_pictures(bonn: Path, tmp: Path, out: Path) -> None:
    """A `full` run on real footage: its figure of x/y/z against ground truth (a plot of our results, committed)
    and its restored frame, written to `LOCAL` only: a frame of the shared data never enters the repository."""
    run = tmp / "bonn_full"
    cli("run", str(bonn), "--out", str(run), "--preset", "full", "--camera", "bonn",
        "--start", str(BONN_START), "--max-frames", str(BONN_FRAMES), "--quiet")
    (out / LOCAL).mkdir(parents=True, exist_ok=True)
    restored_picture(run, out / LOCAL / "restored_frame_bonn.jpg")
    save(read(run / artifacts.PLOT_XYZ), out / "trajectory_xyz.png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "pictures")
    ap.add_argument("--bonn", type=Path,
                    default=Path(os.environ.get("VTD_SHARED_DIR", ROOT.parent / "shared")) / "data" / "bonn_crowd_dev")
    ap.add_argument("--skip-service", action="store_true", help="Only the pictures of the Bonn run.")
    ap.add_argument("--skip-bonn", action="store_true", help="Only the pictures of the service.")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="vtd-pictures-") as t:
        tmp = Path(t)
        if args.skip_bonn:
            pass
        elif args.bonn.is_dir():
            bonn_pictures(args.bonn, tmp, args.out)
        else:
            print(f"no Bonn sequence at {args.bonn}: its pictures are left as they are")
        if not args.skip_service:
            synth_pictures(tmp, args.out)
            service_pictures(tmp, args.out)
    total = sum(p.stat().st_size for p in args.out.iterdir() if p.is_file())
    print(f"docs/pictures: {total // 1024} KiB in all")


if __name__ == "__main__":
    main()
