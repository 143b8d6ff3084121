"""How the browser viewer keeps up: for each built-in scene, the simulated time per wall
second, the updates the server sends per second, and the frames per second the page
draws in headless Chromium (software WebGL, no GPU). Writes results/viewer_realtime.json.

Usage: python benchmarks/viewer_realtime.py [--seconds 6]
Needs Debian's chromium and the test extras (viser, playwright).
"""

from __future__ import annotations

import argparse
import socket
import time

from results_io import RESULTS, run_record, write_json

PAGE_FPS = """() => new Promise(done => { let n = 0; const t0 = performance.now();
  function tick() { n++; if (performance.now() - t0 < 2000) requestAnimationFrame(tick);
  else done(n / ((performance.now() - t0) / 1000)); } requestAnimationFrame(tick); })"""


def main() -> None:
    from playwright.sync_api import sync_playwright

    import softbody as sb
    from softbody.scenes import list_scenes, load_scene
    from softbody.viewer.app import show

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=6.0)
    args = parser.parse_args()
    rows = []
    with sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path="/usr/bin/chromium",
            headless=True,
            args=[
                "--no-sandbox",
                "--enable-unsafe-swiftshader",
                "--disable-background-networking",
                "--no-first-run",
            ],
        )
        for name in list_scenes():
            scene = load_scene(name)
            sim = sb.Simulator(scene.model, integrator=scene.integrator, dt=scene.dt)
            with socket.socket() as s:
                s.bind(("127.0.0.1", 0))
                port = s.getsockname()[1]
            cam = scene.render.camera
            viewer = show(
                scene.model,
                scene.model.state(),
                sim,
                port=port,
                block=False,
                body_names=scene.body_names,
                camera=(cam.eye, cam.target),
            )
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            page.goto(viewer.url)
            page.get_by_text("t = ").first.wait_for(timeout=30_000)
            t_sim, t_wall = viewer.state.time, time.perf_counter()
            time.sleep(args.seconds)
            realtime = (viewer.state.time - t_sim) / (time.perf_counter() - t_wall)
            fps = page.evaluate(PAGE_FPS)
            row = {
                "scene": name,
                "particles": scene.model.particle_count,
                "dt_s": scene.dt,
                "simulated_per_wall_second": realtime,
                "server_updates_per_second": viewer.updates_per_second,
                "page_frames_per_second": fps,
            }
            rows.append(row)
            print(
                f"{name:18s} {realtime:5.2f}x real time, {viewer.updates_per_second:5.1f} "
                f"updates/s, page {fps:5.1f} fps",
                flush=True,
            )
            page.close()
            viewer.stop()
        browser.close()
    out = run_record("viewer_realtime", renderer="headless chromium, software WebGL", scenes=rows)
    write_json(RESULTS / "viewer_realtime.json", out)
    print(f"wrote {RESULTS / 'viewer_realtime.json'}")


if __name__ == "__main__":
    main()
