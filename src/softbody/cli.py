"""The ``softbody`` command line.

    softbody scenes [--show NAME | --copy NAME DEST]
    softbody run SCENE_OR_FILE [--duration S] [--dt S] [--integrator NAME] [--out DIR]
                               [--set KEY=VALUE ...] [--meshes obj|ply] [--usd] ...
    softbody info MESH

User mistakes (unknown scene or key, invalid mesh, unstable settings, a run that blows
up) print one line to stderr and exit with status 2; nothing is written unless the run
succeeds.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

INTEGRATORS = [
    "euler",
    "midpoint",
    "rk4",
    "symplectic_euler",
    "velocity_verlet",
    "implicit_euler",
    "bdf2",
    "projective",
]


def _scenes(args) -> int:
    from softbody.scenes import builtin_scene_text, list_scenes, scene_json_schema

    if args.schema:
        import json

        print(json.dumps(scene_json_schema(), indent=2))
        return 0
    if args.show:
        # built-in scenes only: a path here would print any file the user can read
        print(builtin_scene_text(args.show), end="")
        return 0
    if args.copy:
        name, dest = args.copy
        text = builtin_scene_text(name)
        target = Path(dest)
        if target.is_dir():
            target = target / f"{name}.toml"
        try:
            # "x": never overwrite, even a file created since we looked
            with target.open("x", encoding="utf-8") as f:
                f.write(text)
        except FileExistsError:
            raise ValueError(f"{target} exists; not overwriting it") from None
        print(f"wrote {target} (edit it, then: softbody run {target})")
        return 0
    scenes = list_scenes()
    width = max(len(n) for n in scenes)
    for name, description in scenes.items():
        print(f"{name:<{width}}  {description}")
    return 0


def _run(args) -> int:
    from softbody.run import Outputs, run_scene
    from softbody.scenes import load_scene

    overrides = list(args.set or [])
    if args.velocity_vectors:
        overrides.append("render.velocity_vectors=true")
    if args.style:
        overrides.append(f'render.style="{args.style}"')
    scene = load_scene(args.scene, overrides)
    outputs = Outputs(
        video=not args.no_video, gif=not args.no_gif, meshes=args.meshes, usd=args.usd
    )
    print(
        f"{scene.name}: {scene.model.particle_count} particles, "
        f"{scene.model.tri_count} triangles, {scene.model.body_count} bodies",
        flush=True,
    )
    summary = run_scene(
        scene,
        Path(args.out),
        integrator=args.integrator,
        dt=args.dt,
        duration=args.duration,
        outputs=outputs,
        strict_stability=True,
        progress_stream=sys.stdout,
        threads=args.threads,
    )
    t = summary["timings_s"]
    print(
        f"simulated {summary['duration_s']:.3g} s in {t['simulation']:.2f} s of compute "
        f"({t['simulated_per_wall_second']:.1f}x real time), rendered in "
        f"{t['rendering']:.2f} s (kernels compiled or loaded in "
        f"{t['kernel_compile_or_load']:.1f} s)"
    )
    for path in summary["files"]:
        print(f"wrote {path}")
    return 0


def _view(args) -> int:
    import warnings

    from softbody.errors import StabilityWarning
    from softbody.scenes import load_scene
    from softbody.sim.simulator import Simulator
    from softbody.viewer.app import show

    try:
        import viser  # noqa: F401
    except ImportError:
        raise RuntimeError("the viewer needs viser: pip install -e '.[viewer]'") from None
    scene = load_scene(args.scene, list(args.set or []))
    print(f"{scene.name}: preparing (the first run compiles the kernels, about 40 s)", flush=True)

    with warnings.catch_warnings():
        warnings.simplefilter("error", StabilityWarning)
        sim = Simulator(
            scene.model,
            integrator=args.integrator or scene.integrator,
            dt=args.dt or scene.dt,
            implicit_tolerance=scene.implicit_tolerance,
        )
    cam = scene.render.camera
    viewer = show(
        scene.model,
        scene.model.state(),
        sim,
        host=args.host,
        port=args.port,
        block=False,
        body_names=scene.body_names,
        body_colors=scene.render.body_colors,
        camera=(cam.eye, cam.target),
    )
    print(f"{scene.name}: open {viewer.url} in a browser (Ctrl-C to stop)", flush=True)
    viewer.wait()
    return 0


def _info(args) -> int:
    from softbody.mesh import inspect_mesh, read_mesh

    mesh = read_mesh(args.mesh)
    report = inspect_mesh(mesh)
    print(
        f"{args.mesh}: {report.input_vertex_count} vertices, {report.input_face_count} "
        f"triangles as stored; {report.mesh.vertex_count} vertices after welding"
    )
    print(f"  volume {abs(report.signed_volume):.6g} m^3, area {report.mesh.area:.6g} m^2")
    for line in report.repairs:
        print(f"  repair: {line}")
    if report.problems:
        for line in report.problems:
            print(f"  problem: {line}")
        print("  cannot hold gas")
        return 1
    print("  closed and manifold: can hold gas")
    return 0


def _dt(text: str) -> float | str:
    return "auto" if text == "auto" else _positive_float(text)


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be finite and > 0, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="softbody", description="Pressure soft bodies (Matyka & Ollila)."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    scenes = sub.add_parser("scenes", help="list the built-in scenes, show or copy one")
    group = scenes.add_mutually_exclusive_group()
    group.add_argument("--show", metavar="NAME", help="print a built-in scene's TOML")
    group.add_argument(
        "--copy",
        nargs=2,
        metavar=("NAME", "DEST"),
        help="copy a built-in scene to a file for editing (never overwrites)",
    )
    group.add_argument(
        "--schema",
        action="store_true",
        help="print the scene file's JSON Schema (every key's type, unit, default, bounds)",
    )
    scenes.set_defaults(func=_scenes)

    run = sub.add_parser("run", help="simulate a scene and write video, plots and summary")
    run.add_argument("scene", help="built-in scene name (see `softbody scenes`) or .toml file")
    run.add_argument("--out", default="out", help="output folder (default: out)")
    run.add_argument("--duration", type=_positive_float, help="simulated seconds")
    run.add_argument("--dt", type=_dt, help='time step in seconds, or "auto"')
    run.add_argument("--integrator", choices=INTEGRATORS)
    run.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override a scene value, e.g. --set bodies.0.gas.nrt=50 (repeatable)",
    )
    run.add_argument("--style", choices=["solid", "wireframe", "both"])
    run.add_argument(
        "--velocity-vectors", action="store_true", help="draw vertex velocities (paper, Figure 7)"
    )
    run.add_argument("--meshes", choices=["obj", "ply"], help="also write a mesh per frame")
    run.add_argument("--usd", action="store_true", help="also write a USD point cache")
    run.add_argument(
        "--threads",
        type=int,
        default=1,
        help="threads for the force terms (default 1; pays off only on large meshes)",
    )
    run.add_argument("--no-video", action="store_true", help="skip the MP4")
    run.add_argument("--no-gif", action="store_true", help="skip the GIF")
    run.set_defaults(func=_run)

    view = sub.add_parser("view", help="simulate a scene live in the browser")
    view.add_argument("scene", help="built-in scene name or .toml file")
    view.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    view.add_argument("--port", type=int, default=8080, help="port (default 8080)")
    view.add_argument("--dt", type=_dt, help='time step in seconds, or "auto"')
    view.add_argument("--integrator", choices=INTEGRATORS)
    view.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="override a scene value (repeatable)"
    )
    view.set_defaults(func=_view)

    info = sub.add_parser("info", help="check whether a mesh file can hold gas")
    info.add_argument("mesh", help="OBJ, PLY, STL, OFF or GLB file")
    info.set_defaults(func=_info)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``softbody`` console script."""
    import warnings

    from softbody.errors import MeshError, SimulationError, StabilityWarning

    args = build_parser().parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # repairs are reported by info
            return args.func(args)
    except (MeshError, SimulationError, StabilityWarning, ValueError, RuntimeError, OSError) as exc:
        print(f"softbody: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
