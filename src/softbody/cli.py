"""The ``softbody`` command line.

    softbody scenes [--show NAME | --copy NAME DEST]
    softbody run SCENE_OR_FILE [--duration S] [--dt S] [--integrator NAME] [--out DIR]
                               [--set KEY=VALUE ...] [--meshes obj|ply] [--usd]
                               [--usd-start-frame FRAME] ...
    softbody sweep SWEEP_OR_SCENE [--vary KEY=VALUES ...] [--set KEY=VALUE ...] --out DIR
                                  [--workers N | --address tcp://HOST:PORT] [--samples N]
    softbody info MESH

User mistakes (unknown scene or key, invalid mesh, unstable settings, a run that blows
up, a run too long or too large for this machine, an output folder already holding a
file of a run's names without ``--overwrite``) print one line ``softbody: error: ...``
to stderr and exit with status 2; nothing is written unless the run succeeds. Running
out of memory is one line too (status 2). Ctrl-C, SIGTERM and SIGHUP (the terminal
closed) stop a command with one line, remove its temporary files and child processes,
and exit with 130, 143 and 129 (128 + the signal number); ``softbody view`` too. An
unexpected exception is a bug: one line naming it, status 1; set the environment
variable ``SOFTBODY_DEBUG=1`` to see the traceback as well.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

from softbody.run import MAX_FRAMES, MAX_STEPS

INTEGRATORS = [
    "euler",
    "midpoint",
    "rk4",
    "symplectic_euler",
    "velocity_verlet",
    "implicit_euler",
    "bdf2",
    "projective",
    "xpbd",
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


def _out_folder(text: str) -> Path:
    """``--out``: a folder's name; an empty one (``--out ""``, an unset shell variable)
    is refused rather than read as the current folder."""
    if not text.strip():
        raise ValueError(
            f"--out {text!r} names no folder; give one (--out . for the current folder)"
        )
    return Path(text)


def _run(args) -> int:
    from softbody.run import Outputs, run_scene
    from softbody.scenes import load_scene

    out = _out_folder(args.out)
    overrides = list(args.set or [])
    if args.velocity_vectors:
        overrides.append("render.velocity_vectors=true")
    if args.style:
        overrides.append(f'render.style="{args.style}"')
    if args.usd_start_frame is not None:
        overrides.append(f"render.usd_start_frame={args.usd_start_frame!r}")
    scene = load_scene(args.scene, overrides)
    outputs = Outputs(
        video=not args.no_video,
        gif=not args.no_gif,
        meshes=args.meshes,
        usd=args.usd or args.usd_start_frame is not None,
    )
    print(
        f"{scene.name}: {scene.model.particle_count} particles, "
        f"{scene.model.tri_count} triangles, {scene.model.body_count} bodies",
        flush=True,
    )
    summary = run_scene(
        scene,
        out,
        integrator=args.integrator,
        dt=args.dt,
        duration=args.duration,
        outputs=outputs,
        strict_stability=True,
        progress_stream=sys.stdout,
        threads=args.threads,
        max_steps=args.max_steps,
        max_frames=args.max_frames,
        overwrite=args.overwrite,
    )
    t = summary["timings_s"]
    print(
        f"simulated {summary['duration_s']:.3g} s in {t['simulation']:.2f} s of compute "
        f"({t['simulated_per_wall_second']:.1f}x real time), rendered in "
        f"{t['rendering']:.2f} s (first step {t['kernel_compile_or_load']:.2f} s)"
    )
    replaced = summary["replaced"]
    for path in summary["files"]:
        inside = [p for p in replaced if Path(p).parent == Path(path)]
        if path in replaced:
            print(f"replaced {path}")
        elif inside:
            print(f"wrote {path} (replacing {len(inside)} of its files)")
        else:
            print(f"wrote {path}")
    others = summary["others"]
    if others:
        shown = ", ".join(Path(p).name for p in others[:3]) + (", ..." if len(others) > 3 else "")
        print(
            f"note: {Path(others[0]).parent} also holds {len(others)} file"
            f"{'s' if len(others) != 1 else ''} this run did not write ({shown}); left as "
            f"{'they were' if len(others) != 1 else 'it was'}"
        )
    return 0


def _sweep(args) -> int:
    import softbody.sweep as sweeps
    from softbody.scenes.loader import parse_override

    out = _out_folder(args.out)
    fixed = {}
    for text in args.set or []:
        path, value = parse_override(text)
        fixed[".".join(path)] = value
    vary: dict = {}
    dists: dict = {}
    for text in args.vary or []:
        if "=" not in text:
            raise ValueError(f"--vary {text[:200]!r} must look like key=values")
        key, values = (part.strip() for part in text.split("=", 1))
        parsed = sweeps.parse_values(values, f"--vary {key}")
        (dists if isinstance(parsed, dict) else vary)[key] = parsed
    if dists and args.samples is None:
        raise ValueError("--vary with a distribution needs --samples N")
    random = {"samples": args.samples, "seed": args.seed, "latin": args.latin, "vary": dists}
    if sweeps.is_sweep_file(args.sweep):
        if vary or dists:
            raise ValueError("--vary is for a scene; a sweep file lists its own [vary]")
        spec = sweeps.load_sweep_file(args.sweep, extra_set=fixed)
    else:
        spec = sweeps.build_spec(
            args.sweep,
            vary=vary,
            set=fixed,
            random=random if dists else None,
            metrics=args.metric,
            sample_rate=args.sample_rate,
            label="softbody sweep",
        )
    sweeps._check_dependencies()
    result = sweeps.run_sweep(
        spec,
        out,
        workers=args.workers,
        address=args.address,
        figure=not args.no_figure,
        progress=sys.stdout,
    )
    print(
        f"{result.total} runs: {result.executed} run now, {result.skipped} already done; "
        f"{result.ok} ok, {result.blew_up} blew up, {result.errors} errors "
        f"in {result.wall_time:.1f} s"
    )
    return 0


def _view(args) -> int:
    import warnings

    from softbody.errors import StabilityWarning
    from softbody.scenes import load_scene
    from softbody.sim.simulator import Simulator

    try:
        import viser  # noqa: F401
    except ImportError:
        raise RuntimeError("the viewer needs viser: pip install -e '.[viewer]'") from None
    from softbody.viewer.app import show

    scene = load_scene(args.scene, list(args.set or []))
    print(f"{scene.name}: preparing", flush=True)

    # Ctrl-C or SIGTERM while it starts: main() says so and exits 130 or 143
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
        quiet=True,  # the lines below say it, with the scene's name
    )
    if viewer.exposed:
        print(
            f"softbody: warning: the viewer listens on {args.host}, so it is reachable from "
            "the network; anyone with the token in the URL below can drive it",
            file=sys.stderr,
            flush=True,
        )
    # the token in the URL is the key to the viewer: the page sets it as a cookie
    print(f"{scene.name}: open {viewer.url} in a browser (Ctrl-C to stop)", flush=True)
    try:
        # not viewer.wait(), which ends quietly on Ctrl-C: the signal reaches main(),
        # which exits with 128 + its number as every command does
        while not viewer.closed:
            time.sleep(0.2)
    finally:
        viewer.stop()
    return 0


def _info(args) -> int:
    from softbody.mesh import inspect_mesh, read_mesh

    mesh = read_mesh(args.mesh)
    report = inspect_mesh(mesh, self_intersections=True)  # always here, whatever the size
    print(
        f"{args.mesh}: {report.input_vertex_count} vertices, {report.input_face_count} "
        f"triangles as stored; {report.mesh.vertex_count} vertices after welding"
    )
    print(f"  volume {abs(report.signed_volume):.6g} m^3, area {report.mesh.area:.6g} m^2")
    if not report.self_intersection_count:
        print("  self-intersections: none")
    for line in report.repairs:
        print(f"  repair: {line}")
    for line in report.warnings:
        print(f"  warning: {line}")
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


def _count(text: str) -> int:
    """A whole number >= 1 (``1e9`` and ``1_000_000`` are accepted)."""
    try:
        value = float(text.replace("_", ""))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (value >= 1 and value < 2**63 and value == int(value)):
        raise argparse.ArgumentTypeError(f"must be a whole number from 1 to 2**63 - 1, got {text}")
    return int(value)


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
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="replace this run's files (named after the scene) where they exist already",
    )
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
    run.add_argument(
        "--usd",
        action="store_true",
        help="also write a USD cache (bodies, colliders; points, normals, velocities per frame)",
    )
    run.add_argument(
        "--usd-start-frame",
        type=float,
        metavar="FRAME",
        help="time code of the USD cache's first frame, e.g. 1001 (implies --usd; the scene's "
        "render.usd_start_frame, default 0)",
    )
    run.add_argument(
        "--threads",
        type=int,
        default=1,
        help="threads for the force terms (default 1; pays off only on large meshes)",
    )
    run.add_argument("--no-video", action="store_true", help="skip the MP4")
    run.add_argument("--no-gif", action="store_true", help="skip the GIF")
    run.add_argument(
        "--max-steps",
        type=_count,
        default=MAX_STEPS,
        help=f"refuse a run of more simulation steps (default {MAX_STEPS:,})",
    )
    run.add_argument(
        "--max-frames",
        type=_count,
        default=MAX_FRAMES,
        help=f"refuse a run of more rendered frames (default {MAX_FRAMES:,})",
    )
    run.set_defaults(func=_run)

    sweep = sub.add_parser(
        "sweep", help="run a scene over a grid or random sample of parameters (Dask)"
    )
    sweep.add_argument("sweep", help="sweep file (.toml), built-in scene name or scene file")
    sweep.add_argument("--out", required=True, help="output folder (resumed when rerun)")
    sweep.add_argument(
        "--vary",
        action="append",
        metavar="KEY=VALUES",
        help="a varied key: a list 1,4,16; a range low:high:count[:log]; or with --samples "
        "uniform:low:high, loguniform:low:high, normal:mean:std (repeatable; a grid)",
    )
    sweep.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="override a scene value (repeatable)"
    )
    sweep.add_argument("--samples", type=_count, help="random samples of the distributions")
    sweep.add_argument("--seed", type=int, default=0, help="seed of the random samples")
    sweep.add_argument("--latin", action="store_true", help="Latin hypercube samples")
    sweep.add_argument(
        "--metric", action="append", help="keep only these built-in metrics (repeatable)"
    )
    sweep.add_argument(
        "--sample-rate",
        type=_positive_float,
        default=100.0,
        help="history samples per simulated second (default 100)",
    )
    where = sweep.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        help="local worker processes (default and most: one per available core; 0: no Dask)",
    )
    where.add_argument("--address", help="a running Dask scheduler, e.g. tcp://host:8786")
    sweep.add_argument("--no-figure", action="store_true", help="skip the summary figure")
    sweep.set_defaults(func=_sweep)

    view = sub.add_parser("view", help="simulate a scene live in the browser")
    view.add_argument("scene", help="built-in scene name or .toml file")
    view.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind (default 127.0.0.1; any other is reachable from the network)",
    )
    from softbody.viewer import port_number

    view.add_argument(
        "--port",
        type=port_number,
        default=8080,
        help="port (default 8080; the next free one if taken, 0 for any)",
    )
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


class _Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP (the terminal closed), raised in the main thread so that
    ``finally`` blocks clean up (a KeyboardInterrupt, so that no ``except Exception``
    swallows it)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__()
        self.signum = signum


#: Signals that stop a command as Ctrl-C does: temporary files and child processes are
#: removed and the exit status is 128 + the signal's number.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


def _on_stop_signal(signum, frame) -> None:
    raise _Terminated(signum)


def _warning_printer():
    """A ``warnings.showwarning`` for the CLI: ``softbody: warning: ...`` on one line,
    with no source line or file name of ours, each finding once: a mesh file is validated
    when it is read (``FILE: finding``) and again when its body is built (``body N mesh:
    finding``), and the first names the file."""
    shown: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        text = _one_line(message)
        finding = text.split(": ", 1)[-1]
        if finding not in shown:
            shown.add(finding)
            print(f"softbody: warning: {text}", file=sys.stderr, flush=True)

    return show


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line: an OSError as ``file: reason``; several lines
    joined with ``; ``."""
    if isinstance(exc, OSError) and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    else:
        text = str(exc) or type(exc).__name__
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``softbody`` console script."""
    import warnings

    from softbody.errors import MeshError, MeshWarning, SimulationError, StabilityWarning

    args = build_parser().parse_args(argv)
    debug = os.environ.get("SOFTBODY_DEBUG", "").strip() not in ("", "0")
    in_main = _in_main_thread()
    previous = {sig: signal.signal(sig, _on_stop_signal) for sig in STOP_SIGNALS if in_main}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # other libraries' chatter
            # a mesh that was repaired or crosses itself: one line each, the run goes on
            warnings.simplefilter("default", MeshWarning)
            warnings.showwarning = _warning_printer()
            return args.func(args)
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        name = signal.Signals(signum).name
        print(f"softbody: interrupted ({name})", file=sys.stderr)
        return 128 + int(signum)
    except MemoryError as exc:
        _traceback(debug)
        detail = f" ({_one_line(exc)})" if str(exc) else ""
        print(
            f"softbody: error: out of memory while running `softbody {args.command}`{detail}; "
            "try a smaller mesh, fewer frames or fewer outputs",
            file=sys.stderr,
        )
        return 2
    except BrokenPipeError:
        # the reader went away (`softbody scenes --schema | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (MeshError, SimulationError, StabilityWarning, ValueError, RuntimeError, OSError) as exc:
        _traceback(debug)
        print(f"softbody: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:
        _traceback(debug)
        hint = "" if debug else "; set SOFTBODY_DEBUG=1 to see the traceback"
        print(
            f"softbody: internal error (a bug; please report it): {type(exc).__name__}: "
            f"{_one_line(exc)}{hint}",
            file=sys.stderr,
        )
        return 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)


def _in_main_thread() -> bool:
    """Whether this is the main thread (the only one that may set signal handlers)."""
    import threading

    return threading.current_thread() is threading.main_thread()


def _traceback(debug: bool) -> None:
    if debug:
        import traceback

        traceback.print_exc()


if __name__ == "__main__":
    sys.exit(main())
