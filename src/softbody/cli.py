"""The ``softbody`` command line.

User mistakes (bad arguments, invalid meshes, unstable settings) print one line to stderr
and exit with status 2; nothing is written unless the run succeeds.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path


def _demo(args) -> int:
    from softbody.demo import hanging_balls, write_outputs
    from softbody.errors import StabilityWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error", StabilityWarning)
        result = hanging_balls(
            duration=args.duration,
            dt=args.dt,
            integrator=args.integrator,
            log=(lambda s: print(s, flush=True)),
        )
    paths = write_outputs(result, Path(args.out))
    rate = result.steps / max(result.wall_seconds, 1e-9)
    print(
        f"simulated {result.time[-1]:.3g} s in {result.wall_seconds:.2f} s "
        f"({rate:,.0f} steps/s, {result.model.particle_count} particles)"
    )
    for b, v in enumerate(result.volume[-1]):
        print(
            f"  ball {b}: volume {v:.4f} m^3 (rest {result.model.body_rest_volume[b]:.4f}), "
            f"pressure {result.pressure[-1, b]:.1f} Pa"
        )
    for p in paths:
        print(f"wrote {p}")
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


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be finite and > 0, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    from softbody.demo import DEMO_DEFAULTS

    parser = argparse.ArgumentParser(
        prog="softbody", description="Pressure soft bodies (Matyka & Ollila)."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="hanging balls at several gas amounts (paper Fig. 1)")
    demo.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    demo.add_argument(
        "--duration",
        type=_positive_float,
        default=DEMO_DEFAULTS["duration"],
        help=f"simulated seconds (default {DEMO_DEFAULTS['duration']:g})",
    )
    demo.add_argument(
        "--dt",
        type=_positive_float,
        default=DEMO_DEFAULTS["dt"],
        help=f"time step in seconds (default {DEMO_DEFAULTS['dt']:g})",
    )
    demo.add_argument(
        "--integrator",
        default="midpoint",
        choices=["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet"],
    )
    demo.set_defaults(func=_demo)
    info = sub.add_parser("info", help="check whether a mesh file can hold gas")
    info.add_argument("mesh", help="OBJ, PLY, STL, OFF or GLB file")
    info.set_defaults(func=_info)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``softbody`` console script."""
    from softbody.errors import MeshError, SimulationError, StabilityWarning

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (MeshError, SimulationError, StabilityWarning, ValueError, OSError) as exc:
        print(f"softbody: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
