"""Thickness contacts inside the implicit solve, and crossings the rigid colliders cause
(core/collision/thick_system.hpp)."""

import re

import numpy as np
import pytest

import softbody as sb
from softbody.collision.crossings import edge_crossings
from softbody.mesh.topology import unique_edges

G = 9.81  # [m/s^2]


def ball_on_trampoline(h=0.01):
    """A 0.2 m ball (0.5 kg) dropped from 1.2 h onto a 1 m cloth held at its border (no
    collider: the only contacts are the thickness contacts between the two bodies)."""
    builder = sb.ModelBuilder(gravity=(0, 0, -G))
    builder.set_soft_contact("surface", thickness=h, restitution=0.0, friction=0.3)
    sheet = sb.rectangle((1.0, 1.0), (16, 16))
    v = sheet.vertices
    border = np.nonzero((np.abs(v[:, 0]) > 0.49) | (np.abs(v[:, 1]) > 0.49))[0]
    builder.add_cloth(sheet, mass=0.5, stiffness=2000.0, damping=1.0, pinned=border)
    builder.add_soft_body(sb.icosphere(2, radius=0.2).translated((0.0, 0.0, 0.2 + 1.2 * h)),
                          mass=0.5, stiffness=500.0, damping=1.0, gas=150.0)  # fmt: skip
    return builder.finalize()


@pytest.mark.parametrize(("integrator", "preconditioner"), [("implicit_euler", "multigrid"),
                                                            ("implicit_euler", "jacobi"),
                                                            ("bdf2", "multigrid")])  # fmt: skip
def test_resting_contact_is_carried_by_the_solve(integrator, preconditioner):
    """A ball resting on a held cloth under implicit Euler at 1/60 s (with either
    preconditioner, whose diagonals take the contacts' stiffness; and BDF2, whose update is
    not x0 + dt v1, so the first check below is backward Euler's), over 2-4 s after the
    drop. Reference: backward Euler's own update is x1 = x0 + dt v1 exactly, so
    |x1 - x0 - dt v1| per particle is what the contact stage after the solve changed
    (position moves, and dt times velocity changes). With the contacts in the linear
    system the solve holds the ball in the band above h itself: the stage's largest
    correction per step averages under 1 mm (2.5 cm when only the stage acted: it pushed
    and stopped the ball every step); the kinetic energy at rest (jitter) stays under
    2e-3 J (0.043 J before); and the force the ball receives, from its mass centre's
    velocity change, M (dv/dt + g), averages its weight M g within 1 % and varies by under
    1 % of it (2.6 % before)."""
    dt = 1 / 60
    model = ball_on_trampoline()
    sim = sb.Simulator(model, integrator=integrator, dt=dt,
                       implicit_preconditioner=preconditioner)  # fmt: skip
    state = model.state()
    b0, b1 = model.body_particle_range[1]
    m = model.particle_mass
    ball = m[b0:b1].sum()
    correction, energy, force = [], [], []
    v_prev = 0.0
    for step in range(240):
        q0 = state.particle_q.copy()
        sim.run(state, 1)
        v = state.particle_qd
        vc = (m[b0:b1] * v[b0:b1, 2]).sum() / ball
        if step >= 120:
            correction.append(np.linalg.norm(state.particle_q - q0 - dt * v, axis=1).max())
            energy.append(0.5 * (m[:, None] * v * v).sum())
            force.append(ball * ((vc - v_prev) / dt + G))
        v_prev = vc
    weight = ball * G
    if integrator == "implicit_euler":
        assert np.mean(correction) < 1e-3
    assert np.mean(energy) < 2e-3
    assert abs(np.mean(force) - weight) < 0.01 * weight
    assert np.std(force) < 0.01 * weight
    # it rests on the cloth's dip, not through it
    a0, a1 = model.body_particle_range[0]
    assert state.particle_q[b0:b1, 2].min() > state.particle_q[a0:a1, 2].min()


def two_balls_thrown() -> sb.Model:
    """Two 1 kg gas balls (162 vertices, radius 0.5 m) thrown at each other at (+-1, +-0.5,
    0) m/s, no gravity, surface contacts with a thickness of 2 cm, no friction."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=0.02, restitution=0.5, friction=0.0)
    for x, v in ((-0.53, 1.0), (0.53, -1.0)):
        builder.add_soft_body(sb.icosphere(2, radius=0.5).translated((x, 0.03, 0.0)),
                              mass=1.0, stiffness=500.0, damping=1.0, gas=300.0,
                              velocity=(v, 0.5 * v, 0))  # fmt: skip
    return builder.finalize()


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2"])
def test_contact_in_the_solve_conserves_momentum(integrator):
    """Two balls thrown at each other (no gravity, no friction, no collider) under the
    implicit solvers with the linear solve converged (tolerance 1e-12). Reference: each
    pair's penalty force and stiffness act on its four particles with the gap's barycentric
    weights, which sum to 0 (equal and opposite shares), and the stage after the step
    conserves momentum, so total momentum stays at its start, zero, to round-off while each
    ball's own momentum is turned around by the contact."""
    model = two_balls_thrown()
    sim = sb.Simulator(model, integrator=integrator, dt=5e-3, implicit_tolerance=1e-12)
    state = model.state()
    a0, a1 = model.body_particle_range[0]
    m = model.particle_mass[:, None]
    for _ in range(20):
        sim.run(state, 5)
        assert np.abs((m * state.particle_qd).sum(axis=0)).max() < 1e-9
    assert (m[a0:a1] * state.particle_qd[a0:a1]).sum(axis=0)[0] < 0.5  # slowed or turned


def sheet_and_pushing_box(speed, gap=0.02, h=0.01, margin=None):
    """A 0.4 m cloth at z = 0 and a small cloth 'gap' below it beside the path of a solid
    0.2 m box driven down through the large one at 'speed' (no gravity): the box carries the
    large cloth's middle down and its springs pull the cloth's edges through the small one."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=h, restitution=0.0, friction=0.0,
                             margin=margin)  # fmt: skip
    builder.add_cloth(sb.rectangle((0.4, 0.4), (6, 6)), mass=0.1, stiffness=50.0, damping=0.1)
    builder.add_cloth(sb.rectangle((0.16, 0.2), (4, 4), center=(0.19, 0.0, -gap)), mass=0.1,
                      stiffness=50.0, damping=0.1)  # fmt: skip
    down = sb.MotionTranslation((0.0, 0.0, -speed))
    box = sb.ColliderBox(center=(0.0, 0.0, 0.06), half_extents=(0.1, 0.1, 0.05),
                         restitution=0.0, friction=0.0, motion=down)  # fmt: skip
    builder.add_collider(box)
    return builder.finalize()


def between_bodies(model, q):
    """edge_crossings of one body's edge through another body's triangle."""
    edges = unique_edges(model.tri_indices)
    found = edge_crossings(q, model.tri_indices, edges)
    body = model.particle_body
    return [(e, t) for e, t in found if body[edges[e, 0]] != model.tri_body[t]]


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2", "projective"])
@pytest.mark.parametrize("margin", [None, 0.05])
def test_a_collider_pushing_a_sheet_through_another_stops_the_run_there(integrator, margin):
    """The box collider pushes the large cloth's edges through the small cloth in step 3
    (it acts after the thickness contacts, which cannot hold what it moves). With the
    default margin (h) the steps move more than half of it and take their pairs from swept
    boxes: the check runs the gather's crossing check at the step's end over the pairs of
    triangles with a corner that moved in the contacts; with a 0.05 m margin the steps
    keep the stage's list, and the check tests the edges of the listed vertex-triangle
    pairs touching a particle the box moved. Reference: the
    run stops with Status.CROSSED at that step, naming a particle of one cloth and a
    triangle of the other (which edge the check meets first depends on the list's row
    order) and saying a collider pushed it there, with the state left
    at the step's start, where an independent segment-triangle test (edge_crossings) finds
    no edge of one body through the other's triangles; every earlier step passes that test
    too. Before this check the run went on and stopped one step later, at the next step's
    start."""
    dt = 0.01
    model = sheet_and_pushing_box(2.0, margin=margin)
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    with pytest.raises(sb.SimulationError, match=r"crossed a surface at step 3 .*particle \d+ "
                       r"passes through triangle \d+ \(body (\d)\) after a collider pushed it "
                       r"there") as info:  # fmt: skip
        for _ in range(10):
            sim.run(state, 1)
            assert between_bodies(model, state.particle_q) == []
    assert info.value.step == 3
    body = int(re.search(r"\(body (\d)\) after", str(info.value)).group(1))
    assert model.particle_body[info.value.particle] == 1 - body  # one cloth through the other
    assert state.step_count == 3
    assert between_bodies(model, state.particle_q) == []


def closing_cloths(h: float, dt: float) -> sb.Model:
    """Two parallel 0.4 m cloths 1.45 h apart with thickness contacts h [m] (no gravity, no
    friction), closing at h per step of dt [s] each."""
    speed = h / dt
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=h, restitution=0.0, friction=0.0)
    for z, v in ((0.725 * h, -speed), (-0.725 * h, speed)):
        builder.add_cloth(sb.rectangle((0.4, 0.4), (6, 6), center=(0, 0, z)), mass=0.1,
                          stiffness=50.0, damping=0.1, velocity=(0, 0, v))  # fmt: skip
    return builder.finalize()


def test_an_approach_within_the_band_is_stopped_by_the_solve():
    """Two parallel cloths 1.45 h apart (inside the band h + a = 1.5 h where the contacts
    enter the solve) closing at 2 h per step, implicit Euler. Reference: a lone pair's
    linearised penalty (stiffness 4 m_c / dt^2) ends the step at
    d0 + (-2 h + 4 (1.5 h - d0)) / 5 = 1.09 h, above h, and the cloths' vertices have
    several pairs each (stiffer still): so the solve alone keeps every vertex of one cloth
    above the other by h, and the stage after it, which bounds motion and pushes pairs
    nearer than h, changes nothing (|x1 - x0 - dt v1| = 0 to round-off). Before, the solve
    ran the cloths 2 h into each other and the stage's bound held them."""
    h, dt = 0.01, 1e-3
    model = closing_cloths(h, dt)
    sim = sb.Simulator(model, integrator="implicit_euler", dt=dt)
    state = model.state()
    (a0, a1), (b0, b1) = model.body_particle_range
    q0 = state.particle_q.copy()
    sim.run(state, 1)
    q = state.particle_q
    assert np.abs(q - q0 - dt * state.particle_qd).max() < 1e-12
    assert q[a0:a1, 2].min() - q[b0:b1, 2].max() >= h
    assert q[a0:a1, 2].min() - q[b0:b1, 2].max() < 1.45 * h  # the cloths did close
