"""The cases of the reference trajectories (tools/record_trajectories.py records them,
test_trajectories.py replays them): every built-in scene that the engine stepped before
its port, a model with every term, and surface contacts, each with each integrator."""

from __future__ import annotations

import numpy as np

import softbody as sb
from softbody.scenes.loader import load_scene

STEPS = 200
INTEGRATORS = ["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet",
               "implicit_euler", "bdf2", "projective"]  # fmt: skip
# balloon-drop has air drag, which the engine before the port did not have
SCENES = ["bouncing-balls", "hanging-ball", "hand-punch", "cloth-wind", "bounding-volumes"]
MODELS = ["every-term", "surface-two-balls", "surface-ball-on-cloth"]
CASES = [(name, integrator) for name in SCENES + MODELS for integrator in INTEGRATORS]


def every_term_model() -> tuple[sb.Model, sb.Control]:
    """Every term the engine steps: each volume method and gas law, a schedule, ambient
    pressure, bending springs, a spring between bodies, an attachment, pins driven to
    targets, a grab, external forces, each collider kind with each motion, and bounding
    soft contacts."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.3, center=(-0.5, 0.5, 0.0)), mass=1.0,
                    stiffness=400.0, damping=0.5, gas=sb.Gas.isothermal(40.0),
                    bend_stiffness=20.0, bend_damping=0.1)  # fmt: skip
    b.add_soft_body(
        sb.icosphere(2, radius=0.3, center=(0.2, 0.55, 0.0)), mass=1.0, stiffness=400.0,
        damping=0.5, volume_method="bounding_ellipsoid",
        gas=sb.Gas.adiabatic(30.0, ambient_pressure=5.0, schedule=[(0.0, 30.0), (0.05, 60.0)]),
    )  # fmt: skip
    b.add_soft_body(
        sb.icosphere(1, radius=0.25, center=(0.8, 0.5, 0.1)), mass=0.5, stiffness=300.0,
        damping=0.3, volume_method="monte_carlo", gas=sb.Gas.fixed_pressure(80.0),
    )  # fmt: skip
    b.add_soft_body(
        sb.icosphere(1, radius=0.25, center=(0.0, 1.2, 0.0)), mass=0.5, stiffness=300.0,
        damping=0.3, volume_method="bounding_box", gas=20.0, pinned=[0, 1],
    )  # fmt: skip
    b.add_soft_body(
        sb.icosphere(1, radius=0.2, center=(-0.2, 1.0, 0.3)), mass=0.5, stiffness=300.0,
        damping=0.3, volume_method="bounding_sphere", gas=15.0,
    )  # fmt: skip
    b.add_attachment(5, anchor=(-0.5, 1.0, 0.0), stiffness=50.0, damping=1.0)
    b.add_spring(0, 170, stiffness=30.0, damping=0.2)  # between two bodies, off any ring
    b.add_collider(sb.ColliderPlane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0),
                                    restitution=0.5, friction=0.2))  # fmt: skip
    b.add_collider(sb.ColliderSphere(center=(0.2, 0.1, 0.0), radius=0.2,
                                     motion=sb.MotionOscillation(amplitude=(0.0, 0.1, 0.0),
                                                                 frequency=3.0)))  # fmt: skip
    b.add_collider(
        sb.ColliderBox(center=(0.8, 0.1, 0.0), half_extents=(0.2, 0.1, 0.2),
                       motion=sb.MotionRotation(angular_velocity=(0.0, 2.0, 0.0)))
    )  # fmt: skip
    b.add_collider(
        sb.ColliderBox(center=(0.0, 0.8, 0.0), half_extents=(1.5, 1.2, 1.0), container=True,
                       motion=sb.MotionTranslation(velocity=(0.0, 0.1, 0.0)))
    )  # fmt: skip
    b.set_soft_contact("bounding", restitution=0.4, friction=0.1)
    model = b.finalize()
    control = model.control()
    control.particle_f[10] = (0.0, 2.0, 0.0)
    control.grab_particle = 20
    control.grab_target = np.array([-0.4, 0.9, 0.0])
    control.grab_stiffness, control.grab_damping = 30.0, 0.5
    control.pin_target = model.particle_q[model.pin_particle] + (0.0, 0.05, 0.0)
    return model, control


def surface_model(cloth: bool) -> sb.Model:
    """Surface soft contacts: two balls meeting head on at +-2 m/s from 2 cm apart, or
    (``cloth``) a falling ball hitting a cloth pinned at its corners, at 3 m/s."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, -9.81) if cloth else (0.0, 0.0, 0.0))
    b.set_soft_contact("surface", restitution=0.5, friction=0.3)
    if cloth:
        b.add_cloth(sb.rectangle((1.0, 1.0), (8, 8)), mass=2.0, stiffness=2000.0, damping=0.5,
                    pinned=[0, 8, 72, 80])  # fmt: skip
        centers, velocities = [(0.05, -0.03, 0.27)], [(0.0, 0.0, -3.0)]
    else:
        centers, velocities = [(-0.31, 0.0, 0.0), (0.31, 0.02, 0.0)], [(2, 0, 0), (-2, 0, 0)]
    for center, velocity in zip(centers, velocities, strict=True):
        b.add_soft_body(sb.icosphere(2, radius=0.3 if not cloth else 0.25, center=center),
                        mass=1.0, stiffness=400.0, damping=0.5, gas=40.0,
                        velocity=velocity)  # fmt: skip
    return b.finalize()


def build_case(name: str, integrator: str) -> tuple[sb.Model, sb.Control | None, float]:
    """(model, control or None, dt [s]) of a case; scenes run with their own step."""
    if name in SCENES:
        scene = load_scene(name)
        return scene.model, None, scene.dt
    if name == "every-term":
        model, control = every_term_model()
        return model, control, 2e-4
    return surface_model(name == "surface-ball-on-cloth"), None, 2e-4
