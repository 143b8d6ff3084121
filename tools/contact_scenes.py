"""Draw the contact scenes of issue 32 for the docs: three frames of each of
``vacuum-gripper``, ``balloon-ring`` and ``cloth-stair`` side by side, rendered with the
scene's own camera by the project's renderer, written to docs/images/NAME.png.

    PYTHONPATH=src python tools/contact_scenes.py [OUT_DIR] [NAME ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

import softbody as sb
from softbody.render.frame import FrameRenderer
from softbody.scenes import load_scene

#: The times [s] drawn of each scene.
TIMES = {
    "vacuum-gripper": (0.0, 0.5, 1.5),
    "balloon-ring": (0.3, 0.6, 2.0),
    "cloth-stair": (0.3, 0.9, 2.0),
}

#: Width [px] of each frame in the strip.
WIDTH = 360


def strip(name: str) -> Image.Image:
    """The frames of scene ``name`` at TIMES[name], side by side."""
    scene = load_scene(name)
    model = scene.model
    settings = scene.render
    renderer = FrameRenderer(model, settings, open_bodies=model.body_closed == 0)
    sim = sb.Simulator(model, integrator=scene.integrator, dt=scene.dt)
    state = model.state()
    frames = []
    for t in TIMES[name]:
        if t > state.time:
            sim.advance(state, t - state.time, progress=False)
        image = Image.fromarray(np.asarray(renderer.render(state)))
        height = round(image.height * WIDTH / image.width)
        frames.append(image.resize((WIDTH, height), Image.LANCZOS))
    out = Image.new("RGB", (WIDTH * len(frames), frames[0].height), "white")
    for k, f in enumerate(frames):
        out.paste(f, (WIDTH * k, 0))
    return out


def main(out: Path, names: list[str]) -> None:
    for name in names:
        path = out / f"{name}.png"
        strip(name).save(path, optimize=True)
        print(f"wrote {path}")


if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else root / "docs" / "images",
         sys.argv[2:] or list(TIMES))  # fmt: skip
