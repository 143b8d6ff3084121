"""Shared helpers: small models with known physics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import settings

import softbody as sb

# fixed seeds: hypothesis draws the same examples every run
settings.register_profile("softbody", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("softbody")


#: The built-in scenes, in the order the scene tests expect them.
BUILT_IN = [
    "bouncing-balls",
    "hanging-ball",
    "hand-punch",
    "cloth-wind",
    "bounding-volumes",
    "balloon-drop",
    "landing-cushion",
    "airbag",
    "punctured-ball",
    "two-balloons",
    "balloon-tank",
    "bending-actuator",
    "vacuum-gripper",
    "balloon-ring",
    "cloth-stair",
]


def ball_model(
    *,
    subdivisions: int = 2,
    radius: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 500.0,
    damping: float = 0.0,
    gas: sb.Gas | float = 300.0,
    gravity=(0.0, 0.0, 0.0),
    volume_method: str = "exact",
    center=(0.0, 0.0, 0.0),
    **kwargs,
) -> sb.Model:
    """One icosphere ball; no gravity unless asked."""
    builder = sb.ModelBuilder(gravity=gravity)
    builder.add_soft_body(
        sb.icosphere(subdivisions, radius=radius, center=center),
        mass=mass,
        stiffness=stiffness,
        damping=damping,
        gas=gas,
        volume_method=volume_method,
        **kwargs,
    )
    return builder.finalize()


def simulator_past_estimate(model: sb.Model, integrator: str, dt: float) -> sb.Simulator:
    """A Simulator that may run above the stability estimate without its warning, for
    tests of properties that hold at any step (explicit Euler's estimate is tiny: it
    amplifies undamped vibration at any dt, and the estimate counts the pressure
    stiffness as undamped)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        return sb.Simulator(model, integrator=integrator, dt=dt)


def deformed(model: sb.Model, seed: int, amplitude: float) -> sb.State:
    """The model's state with every particle moved randomly by up to ``amplitude`` [m]."""
    rng = np.random.default_rng(seed)
    state = model.state()
    state.particle_q += rng.uniform(-amplitude, amplitude, state.particle_q.shape)
    return state


def forces(model: sb.Model, state: sb.State, control: sb.Control | None = None) -> np.ndarray:
    """Total force on each particle (N, 3) [N] from the compiled core's force terms."""
    from softbody import _core
    from softbody.core import core_model
    from softbody.sim.control import control_data

    c = control_data(model) if control is None else control.write(model, control_data(model))
    state.conform(model)
    q, qd = state.particle_q, state.particle_qd
    return _core.eval_forces(core_model(model), c, float(state.time), q, qd)[0]


def settle(
    model: sb.Model, *, dt: float = 5e-4, speed: float = 1e-11, max_steps: int = 40_000
) -> sb.State:
    """Run a damped model with RK4 until every particle is slower than ``speed`` [m/s]."""
    sim = sb.Simulator(model, integrator="rk4", dt=dt)
    state = model.state()
    while np.abs(state.particle_qd).max() > speed or state.step_count == 0:
        if state.step_count >= max_steps:
            raise AssertionError(f"did not settle in {max_steps} steps")
        sim.run(state, 500)
    return state


def uniform_scaling_stationary(stiffness: float, rest_lengths: np.ndarray, nrt: float) -> float:
    """Scale s where E(s) = 1/2 k (s - 1)^2 sum L0^2 - nRT ln(s^3 V0) is stationary:
    k s (s - 1) sum L0^2 = 3 nRT, so s = (1 + sqrt(1 + 12 nRT / (k sum L0^2))) / 2."""
    return (1 + np.sqrt(1 + 12 * nrt / (stiffness * np.sum(rest_lengths**2)))) / 2


def free_port() -> int:
    """A loopback port free at the time of asking (for a command line that needs a
    number; a library call can pass port 0)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_viewer(**options):
    """The hanging-ball scene in a viewer on a free loopback port, its simulator built
    with ``options`` (keyword options of ``Simulator``)."""
    from softbody.scenes import load_scene
    from softbody.viewer.app import show

    scene = load_scene("hanging-ball")
    sim = sb.Simulator(scene.model, integrator=scene.integrator, dt=scene.dt, **options)
    return show(
        scene.model, scene.model.state(), sim, port=0, block=False, body_names=scene.body_names
    )


def package_copy(folder: Path) -> dict:
    """Copy the installed package, compiled core and generated fields included, into
    ``folder/softbody``; return the environment under which ``python -S`` imports that
    copy: -S skips the site hooks, so an editable install's import redirect cannot hand
    the child the original, and the environment's packages come through PYTHONPATH."""
    import os
    import shutil
    import sysconfig

    from softbody import _core
    from softbody.sim import _model_fields

    source = Path(sb.__file__).parent
    shutil.copytree(
        source, folder / "softbody", ignore=shutil.ignore_patterns("__pycache__", "_core*")
    )
    shutil.copy2(_core.__file__, folder / "softbody" / Path(_core.__file__).name)
    # generated by the build beside the core (an editable install keeps it out of src/)
    shutil.copy2(_model_fields.__file__, folder / "softbody" / "sim" / "_model_fields.py")
    site = sysconfig.get_paths()
    paths = dict.fromkeys([str(folder), site["purelib"], site["platlib"]])
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
