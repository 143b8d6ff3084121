"""Compile every kernel in one process: ``python -m softbody._kernel_warmup FOLDER``.

Run by :func:`softbody._kernel_cache.configure` in a child process when the kernel cache
for this version of the sources is missing; the child's cache is ``FOLDER``
(``SOFTBODY_KERNEL_FOLDER``), which the parent renames into place when this exits 0.
Every path a run, the viewer, the diagnostics and the CLI's outputs take through the
compiled code is exercised here: each integrator family's time loop, the threaded force
terms, both soft-contact modes, every volume method, the stability estimate, the
multigrid and projective set-up and the measurements.
"""

from __future__ import annotations

import sys
import warnings


def exercise() -> None:
    """Run a little of everything that calls compiled code, so that all of it compiles
    in this process."""
    import numba

    import softbody as sb
    from softbody.diagnostics import body_volume_by
    from softbody.integrators.workspace import Workspace
    from softbody.render.frame import FrameRenderer
    from softbody.scenes import list_scenes, load_scene

    warnings.simplefilter("ignore")
    integrators = ["midpoint", "rk4", "euler", "symplectic_euler", "velocity_verlet"]
    integrators += ["implicit_euler", "bdf2", "projective"]
    for name in list_scenes():
        scene = load_scene(name)
        model = scene.model
        for integrator in integrators:
            if model.has_drag and integrator not in [*integrators[:5], "projective"]:
                continue  # drag runs on the compiled core's solvers only
            dt = 1e-4 if integrator in integrators[:5] else 1e-3
            sim = sb.Simulator(model, integrator=integrator, dt=dt)
            state = model.state()
            sim.run(state, 2, model.control())
            sim.run(state, 1)
            if sim._core is not None and not model.has_drag:
                # the Numba loop the core replaced: the tests compare the two
                sim._core = None
                sim.run(state, 2, model.control())
                sim.run(state, 1)
        Workspace.for_model(model, chunk_count=2)  # the partition kernels, at any core count
        threads = min(2, numba.config.NUMBA_NUM_THREADS)
        if threads > 1 and not model.has_drag:
            sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4, threads=threads)
            sim.run(model.state(), 2)
        state = model.state()
        sb.Simulator(model, integrator="midpoint", dt="auto").advance(state, 1e-3)
        sb.body_volume(model, state)
        sb.body_pressure(model, state)
        sb.energies(model, state, model.control())
        for method in ("exact", "bounding_box", "bounding_sphere", "bounding_ellipsoid"):
            body_volume_by(model, state, method)
        body_volume_by(model, state, "monte_carlo")
        renderer = FrameRenderer(model, scene.render, open_bodies=model.body_closed == 0)
        renderer.render(state)
    # both soft-contact modes and a Monte Carlo body
    for mode in ("surface", "bounding"):
        builder = sb.ModelBuilder()
        builder.set_soft_contact(mode)
        for x in (0.0, 2.1):
            builder.add_soft_body(
                sb.icosphere(1, center=(x, 0.0, 0.0)),
                mass=1.0,
                stiffness=100.0,
                damping=0.1,
                gas=10.0,
                volume_method="monte_carlo",
                monte_carlo_samples=64,
            )
        model = builder.finalize()
        for integrator in integrators:
            dt = 1e-4 if integrator in integrators[:5] else 1e-3
            sb.Simulator(model, integrator=integrator, dt=dt).run(model.state(), 2)


def exercise_internals() -> None:
    """The internal kernels the test suite calls on their own from Python (the multigrid
    V-cycle, the smoother's sums), with the argument kinds it passes: compiled here, so
    that no process compiles a kernel into the cache after this one."""
    import numba
    import numpy as np

    import softbody as sb
    from softbody.integrators import implicit as im
    from softbody.integrators.multigrid import apply_multigrid

    builder = sb.ModelBuilder()
    builder.add_soft_body(sb.icosphere(2), mass=1.0, stiffness=100.0, damping=0.1, gas=10.0)
    model = builder.finalize()
    # the Numba explicit loop, which the compiled core replaced: the tests compare the core
    # with it (Simulator._core = None), on one thread and on two
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    for integrator in ("midpoint", "rk4", "euler", "symplectic_euler", "velocity_verlet"):
        for count in sorted({1, threads}):
            sim = sb.Simulator(model, integrator=integrator, dt=1e-4, threads=count)
            sim._core = None
            sim.run(model.state(), 2, model.control())
    sim = sb.Simulator(model, integrator="implicit_euler", dt=1e-2)
    sim.run(model.state(), 1)
    mg, n = sim._multigrid, model.particle_count
    r, z, x = np.ones((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    apply_multigrid(mg, r, z)
    for i in np.flatnonzero(model.particle_inv_mass > 0)[:2]:
        im._offdiagonal_sum(mg, i, x)
        im._entries_sum(mg, x, im._first_later_entry(mg, i), mg.vertex_spring_ptr[i + 1])
    # projective dynamics' Numba loop: the compiled core steps it at threads=1, and the
    # tests compare the two
    sim = sb.Simulator(model, integrator="projective", dt=1e-2)
    sim._core = None
    sim.run(model.state(), 1)


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python -m softbody._kernel_warmup FOLDER", file=sys.stderr)
        return 2
    exercise()
    exercise_internals()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
