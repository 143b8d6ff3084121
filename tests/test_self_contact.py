"""Self-contact and surface contact with a thickness (core/collision/thick.hpp)."""

import subprocess
import sys
import tomllib

import numpy as np
import pytest

import softbody as sb
from softbody.collision.crossings import edge_crossings
from softbody.diagnostics import body_volume
from softbody.mesh.topology import unique_edges


def test_crossing_check_finds_a_known_crossing():
    """The independent check the tests below use (softbody.collision.crossings), against
    its own reference: an edge through the middle of a triangle is found, an edge beside it
    or ending on its plane is not, and an edge sharing a vertex is left out."""
    q = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, -1], [0.2, 0.2, 1],
                  [2, 2, -1], [2, 2, 1], [0.2, 0.2, 0.5]], dtype=float)  # fmt: skip
    tri = np.array([[0, 1, 2]])
    edges = np.array([[3, 4], [5, 6], [7, 4], [0, 4]])
    assert edge_crossings(q, tri, edges).tolist() == [[0, 0]]


def test_crossing_check_grid_finds_every_pair():
    """The check's grid broad phase against every edge-triangle pair: on a seeded random
    soup of 400 triangles (thousands of crossings) it finds exactly the crossings a test
    of all pairs finds (the same segment-plane and sub-area test, without boxes or grid)."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(300, 3))
    tri = rng.integers(0, 300, size=(400, 3))
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])]
    edges = unique_edges(tri)
    e, t = (g.ravel() for g in np.meshgrid(np.arange(len(edges)), np.arange(len(tri)),
                                           indexing="ij"))  # fmt: skip
    i, j = q[edges[e, 0]], q[edges[e, 1]]
    a, b, c = q[tri[t, 0]], q[tri[t, 1]], q[tri[t, 2]]
    apart = ~np.any(tri[t][:, :, None] == edges[e][:, None, :], axis=(1, 2))
    n = np.cross(b - a, c - a)
    da, db = np.sum((i - a) * n, axis=1), np.sum((j - a) * n, axis=1)
    straddle = da * db < 0
    x = i + (da / np.where(straddle, da - db, 1.0))[:, None] * (j - i)
    w = [np.sum(np.cross(u - x, v - x) * n, axis=1) for u, v in ((b, c), (c, a), (a, b))]
    hit = apart & straddle & (w[0] > 0) & (w[1] > 0) & (w[2] > 0)
    brute = set(zip(e[hit].tolist(), t[hit].tolist(), strict=True))
    found = set(map(tuple, edge_crossings(q, tri, edges).tolist()))
    assert len(brute) > 1000
    assert found == brute


# -- the vacuum-packed ball ------------------------------------------------------------------
AMBIENT = 500.0  # [Pa]


def vacuum_ball(subdivisions=3, *, thickness=None, self_contact=True):
    """A 0.5 m ball at its rest volume in balance with a 500 Pa ambient pressure, whose gas
    is drawn down to 2 % over 0.3 s (no gravity)."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    if self_contact:
        builder.set_soft_contact("surface", self_contact=True, thickness=thickness,
                                 restitution=0.0, friction=0.1)  # fmt: skip
    mesh = sb.icosphere(subdivisions, radius=0.5)
    volume = 4.0 / 3.0 * np.pi * 0.5**3
    nrt = AMBIENT * volume
    builder.add_soft_body(
        mesh,
        mass=1.0,
        stiffness=200.0,
        damping=0.5,
        gas=sb.Gas.isothermal(nrt, ambient_pressure=AMBIENT,
                              schedule=[(0.0, nrt), (0.3, 0.02 * nrt)]),
        bend_stiffness=0.0,
    )  # fmt: skip
    return builder.finalize()


def run_sampled(model, integrator, dt, duration, every=0.05):
    """Runs the model, checking every `every` s: (times, volumes, crossings per frame)."""
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    edges = unique_edges(model.tri_indices)
    per = max(1, round(every / dt))
    times, volumes, crossings = [], [], []
    while state.time < duration - 1e-9:
        sim.run(state, per)
        times.append(state.time)
        volumes.append(body_volume(model, state)[0])
        crossings.append(len(edge_crossings(state.particle_q, model.tri_indices, edges)))
    return np.array(times), np.array(volumes), np.array(crossings)


@pytest.mark.parametrize(("integrator", "dt"), [("velocity_verlet", 1.2e-3),
                                                ("implicit_euler", 1 / 240)])  # fmt: skip
def test_vacuum_packed_ball_folds_without_crossing(integrator, dt):
    """The vacuum-packed ball (issue 32; 642 vertices): its gas drawn down to 2 % under a
    500 Pa ambient pressure, it folds flat. Reference: an independent NumPy segment-triangle
    test (edge_crossings) finds no edge through a non-adjacent triangle at any frame
    sampled every 0.05 s; its volume falls under a third of the start and stays positive
    (two sheets held h apart enclose about area / 2 x h: the floor). Without self-contact
    the same run does cross (the check bites)."""
    model = vacuum_ball()
    v0 = body_volume(model, model.state())[0]
    times, volumes, crossings = run_sampled(model, integrator, dt, 0.6)
    assert crossings.max() == 0, f"crossings at t = {times[crossings > 0]}"
    assert volumes.min() > 0
    assert volumes[-1] < v0 / 3
    assert volumes[-1] > 0.5 * 0.5 * 4 * np.pi * 0.5**2 * model.contact_thickness  # held apart
    _, _, without = run_sampled(vacuum_ball(self_contact=False), integrator, dt, 0.6)
    assert without.max() > 0


# -- momentum, tunnelling, every solver ----------------------------------------------------
def thrown_balls(friction=0.0, thickness=0.02):
    """Two 0.5 m balls thrown at each other at +-2 m/s, no gravity."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", self_contact=True, thickness=thickness,
                             restitution=0.5, friction=friction)  # fmt: skip
    for x, v in ((-0.6, 2.0), (0.6, -2.0)):
        builder.add_soft_body(sb.icosphere(2, radius=0.5).translated((x, 0.03, 0.0)),
                              mass=1.0, stiffness=500.0, damping=1.0, gas=300.0,
                              velocity=(v, 0.5 * v, 0))  # fmt: skip
    return builder.finalize()


def momentum(model, state):
    return (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_soft_soft_contact_conserves_momentum(friction):
    """Two balls thrown at each other (no gravity), with surface contacts with a thickness
    and self-contact: every contact impulse and position correction is shared between the
    pair's particles by mass and barycentric weight with an equal and opposite one, so the
    total momentum stays at its start (+-1 kg x (2, 1, 0) m/s: zero) to round-off at every
    step, with friction too, while each ball's momentum changes by a lot (they bounce)."""
    model = thrown_balls(friction)
    sim = sb.Simulator(model, integrator="midpoint", dt=2e-4)
    state = model.state()
    a0, a1 = model.body_particle_range[0]
    for _ in range(40):
        sim.run(state, 50)
        assert np.abs(momentum(model, state)).max() < 1e-12
    p0 = (model.particle_mass[a0:a1, None] * state.particle_qd[a0:a1]).sum(axis=0)
    assert p0[0] < -0.3  # ball 0 came back


def sheets(speed, thickness=0.01, gap=0.05, self_contact=False, margin=None):
    """Two parallel 0.4 m square cloths 'gap' apart, flying at each other at +-speed."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=thickness, restitution=0.0, friction=0.0,
                             self_contact=self_contact, margin=margin)  # fmt: skip
    for z, v in ((0.5 * gap, -speed), (-0.5 * gap, speed)):
        builder.add_cloth(sb.rectangle((0.4, 0.4), (6, 6), center=(0, 0, z)), mass=0.1,
                          stiffness=50.0, damping=0.1, velocity=(0, 0, v))  # fmt: skip
    return builder.finalize()


ALL_SOLVERS = ["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet",
               "implicit_euler", "bdf2", "projective", "xpbd"]  # fmt: skip


@pytest.mark.parametrize("integrator", ALL_SOLVERS)
@pytest.mark.parametrize("steps_per_h", [3, 30])
def test_fast_sheets_do_not_tunnel(integrator, steps_per_h):
    """Two thin sheets 5 h apart approaching at a speed that moves each 3 h (and 30 h) per
    step: a step's motion is bounded (a pair's relative motion at most 0.4 of its distance
    at the step's start), so in every solver neither sheet passes through the other.
    Reference: the sheets' heights keep their order at every step (sheet 0 above sheet 1)
    and edge_crossings finds no edge through a triangle; with the contacts off the same
    run passes through."""
    dt, h = 1e-3, 0.01
    speed = steps_per_h * h / dt
    for contact in (True, False):
        model = sheets(speed, thickness=h)
        if not contact:
            builder_off = sb.ModelBuilder(gravity=(0, 0, 0))
            for z, v in ((0.025, -speed), (-0.025, speed)):
                builder_off.add_cloth(sb.rectangle((0.4, 0.4), (6, 6), center=(0, 0, z)),
                                      mass=0.1, stiffness=50.0, damping=0.1,
                                      velocity=(0, 0, v))  # fmt: skip
            model = builder_off.finalize()
        sim = sb.Simulator(model, integrator=integrator, dt=dt)
        state = model.state()
        (a0, a1), (b0, b1) = model.body_particle_range
        edges = unique_edges(model.tri_indices)
        ordered = True
        for _ in range(10):
            sim.run(state, 1)
            z = state.particle_q[:, 2]
            ordered &= bool(z[a0:a1].min() > z[b0:b1].max())
            if contact:
                assert len(edge_crossings(state.particle_q, model.tri_indices, edges)) == 0
        assert ordered == contact


@pytest.mark.parametrize("integrator", ["symplectic_euler", "implicit_euler"])
def test_a_sheet_turning_fast_after_slow_steps_does_not_tunnel(integrator):
    """The pair list kept between steps sizes its skin from the motion it saw: after 200
    slow steps (the sheets, 6 h apart, closing at 0.002 h per step: the list, built with a
    thin skin, holds none of their pairs and serves many steps) the sheets are thrown at
    each other at 30 h per step. Reference: the
    bound's proof (a step whose motion passes the list's skin builds the list again or takes
    the swept boxes): the sheets' heights keep their order at every later step and
    edge_crossings finds no edge through a triangle, and they end held apart."""
    h, dt = 0.01, 1e-3
    model = sheets(0.001 * h / dt, thickness=h, gap=6 * h, self_contact=True)
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    (a0, a1), (b0, b1) = model.body_particle_range
    sim.run(state, 200)
    fast = 15.0 * h / dt  # each sheet 15 h per step: 30 h per step closing
    state.particle_qd[a0:a1, 2] = -fast
    state.particle_qd[b0:b1, 2] = fast
    edges = unique_edges(model.tri_indices)
    for _ in range(10):
        sim.run(state, 1)
        z = state.particle_q[:, 2]
        assert z[a0:a1].min() > z[b0:b1].max()
        assert len(edge_crossings(state.particle_q, model.tri_indices, edges)) == 0
    gap = state.particle_q[a0:a1, 2].min() - state.particle_q[b0:b1, 2].max()
    assert gap > 0.25 * h


def test_a_fold_approaching_within_the_list_is_caught():
    """A listed pair that starts far (beyond the rows a step reads) and closes over many
    steps: one cloth folded in a U (self-contact, one body), its upper flat part 8 h above
    its lower one, thrown down at 0.05 h per step. Reference: the sheets never pass (no edge
    through a triangle at any sampled step; the upper part stays above the lower), they
    meet (their gap falls under 2 h) and are held at least h / 2 apart."""
    h, dt, r = 0.01, 1e-3, 0.04  # the fold's radius: the flat parts 2 r = 8 h apart
    flat = 0.15
    cloth = sb.rectangle((2 * flat + np.pi * r, 0.2), (17, 8))
    s, y = cloth.vertices[:, 0] - cloth.vertices[:, 0].min(), cloth.vertices[:, 1]
    angle = np.clip((s - flat) / r, 0.0, np.pi)
    x = np.where(s <= flat, s, flat + r * np.sin(angle))
    x = np.where(s >= flat + np.pi * r, flat - (s - flat - np.pi * r), x)
    z = r - r * np.cos(angle)
    mesh = sb.TriMesh(np.stack([x, y, z], axis=1), cloth.faces)
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", self_contact=True, thickness=h, restitution=0.0,
                             friction=0.0)  # fmt: skip
    builder.add_cloth(mesh, mass=0.1, stiffness=50.0, damping=0.1)
    model = builder.finalize()
    assert model.body_count == 1
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=dt)
    state = model.state()
    upper = np.flatnonzero(s >= flat + np.pi * r - 1e-9)
    # each upper vertex's partner: the lower vertex below it at the start
    start = state.particle_q
    below = np.array([np.flatnonzero((s <= flat + 1e-9) & (np.abs(start[:, 0] - start[i, 0])
                                     < 1e-9) & (np.abs(start[:, 1] - start[i, 1]) < 1e-9))[0]
                      for i in upper])  # fmt: skip
    state.particle_qd[upper, 2] = -0.05 * h / dt
    edges = unique_edges(model.tri_indices)
    gaps = []
    for _ in range(30):
        sim.run(state, 20)
        zs = state.particle_q[:, 2]
        gaps.append((zs[upper] - zs[below]).min())
        assert len(edge_crossings(state.particle_q, model.tri_indices, edges)) == 0
    assert min(gaps) > 0.5 * h
    assert min(gaps) < 2 * h


def test_listed_pairs_beyond_the_rows_read_are_read_once_the_list_drifts():
    """A step reads only the list's rows whose build distance is below 2 (drift + motion)
    + h. Two sheets listed 2.5 h apart (margin 3 h: a skin of at least 3 h, so the list
    serves until the sheets have closed by 3 h) closing slowly at 0.02 h per step: their
    rows must be read once the drift since the build reaches 0.75 h, or the sheets pass
    each other before the list is built again. Reference: the sheets' heights keep their
    order at every step, no edge passes through a triangle, and they end held at least
    h / 2 and at most 2 h apart."""
    h, dt = 0.01, 1e-3
    model = sheets(0.01 * h / dt, thickness=h, gap=2.5 * h, self_contact=True, margin=3 * h)
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=dt)
    state = model.state()
    (a0, a1), (b0, b1) = model.body_particle_range
    edges = unique_edges(model.tri_indices)
    for _ in range(30):
        sim.run(state, 5)
        z = state.particle_q[:, 2]
        assert z[a0:a1].min() > z[b0:b1].max()
        assert len(edge_crossings(state.particle_q, model.tri_indices, edges)) == 0
    gap = state.particle_q[a0:a1, 2].mean() - state.particle_q[b0:b1, 2].mean()
    assert 0.5 * h < gap < 2 * h


def test_a_pair_list_past_its_most_room_stops_the_run():
    """A thickness far larger than the body (2 m on a 0.5 m ball of 5,120 triangles) makes
    every vertex-triangle and edge-edge pair a candidate: about 8,300 pairs a triangle, past
    the 4,096 the pair list grows to. Reference: the run stops at step 0 with
    Status.NEED_PAIRS, its message naming the contact pair list and the pairs it needed
    (not the hash's grid cells), and the state is left at its start."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", self_contact=True, thickness=2.0)
    builder.add_soft_body(sb.icosphere(4, radius=0.5), mass=1.0, stiffness=100.0, gas=100.0)
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4)
    state = model.state()
    with pytest.raises(sb.SimulationError, match=r"at step 0.*contact pair list needs \d+ "
                       r"pairs, over 4096 per triangle \(5120 triangles\)") as info:  # fmt: skip
        sim.run(state, 3)
    assert "grid cells" not in str(info.value)
    assert np.array_equal(state.particle_q, model.particle_q)
    pairs = int(str(info.value).split("needs ")[1].split()[0])
    assert pairs > 4096 * 5120


def folded_cloth(h, r=0.04, flat=0.15):
    """One cloth (0.1 kg, one body, self-contact, thickness h, no restitution or friction)
    folded in a U about the y axis: two flat parts 2 r apart joined by a half cylinder.
    Returns the model and each upper vertex's partner below it at the start (upper, below:
    particle indices)."""
    cloth = sb.rectangle((2 * flat + np.pi * r, 0.2), (17, 8))
    s = cloth.vertices[:, 0] - cloth.vertices[:, 0].min()
    angle = np.clip((s - flat) / r, 0.0, np.pi)
    x = np.where(s <= flat, s, flat + r * np.sin(angle))
    x = np.where(s >= flat + np.pi * r, flat - (s - flat - np.pi * r), x)
    z = r - r * np.cos(angle)
    mesh = sb.TriMesh(np.stack([x, cloth.vertices[:, 1], z], axis=1), cloth.faces)
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", self_contact=True, thickness=h, restitution=0.0,
                             friction=0.0)  # fmt: skip
    builder.add_cloth(mesh, mass=0.1, stiffness=50.0, damping=0.1)
    model = builder.finalize()
    q = model.particle_q
    upper = np.flatnonzero(s >= flat + np.pi * r - 1e-9)
    below = np.array([np.flatnonzero((s <= flat + 1e-9) & (np.abs(q[:, 0] - q[i, 0]) < 1e-9)
                                     & (np.abs(q[:, 1] - q[i, 1]) < 1e-9))[0]
                      for i in upper])  # fmt: skip
    return model, upper, below


@pytest.mark.parametrize("motion", ["squeeze", "spin", "shear"])
def test_a_fold_closing_by_an_affine_drift_is_caught(motion):
    """The pair list's drift model: an affine map I + A of the build positions (and a
    residual) bounds a pair's distance at q0 from below by sigma_min(I + A) D_b - 2 max|e|,
    so a body that squeezes, spins or shears keeps its list while no pair can come near,
    and must rebuild it when the map's smallest stretch brings far pairs near. The U-folded
    cloth's flat parts start 8 h apart; every particle's velocity is an affine field in x:
    a squeeze along z closing them at 0.1 h per step (rate k = 12.5 / s about the fold's
    middle plane), with, for spin, a turn at 1.5 rad/s about the y axis through its centre
    (the parts' gap closes to about h: 2 r omega / sqrt(k^2 + omega^2)), or, for shear, x
    sliding at k (z - r). The drift is affine but for the springs, so its residual stays
    small while the parts close by 7 h over about 70 steps: a drift model that left out
    the stretch (or took any stretch as 1) would keep the first list, which holds none of
    their pairs, and the parts would pass. Reference: no edge through a triangle at any
    sampled step (edge_crossings), the parts never nearer than h / 2 (the nearest vertices
    of the two parts), and they meet (nearer than 2.5 h at some step)."""
    h, dt, r = 0.01, 1e-3, 0.04
    model, upper, below = folded_cloth(h, r)
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=dt)
    state = model.state()
    q = state.particle_q
    k = 0.05 * h / (dt * r)
    v = np.zeros_like(q)
    v[:, 2] = -k * (q[:, 2] - r)
    if motion == "spin":
        v += np.cross([0.0, 1.5, 0.0], q - q.mean(axis=0))
    if motion == "shear":
        v[:, 0] = k * (q[:, 2] - r)
    state.particle_qd[:] = v
    edges = unique_edges(model.tri_indices)
    nearest = []
    for _ in range(30):
        sim.run(state, 20)
        p = state.particle_q
        assert len(edge_crossings(p, model.tri_indices, edges)) == 0
        d = np.linalg.norm(p[upper][:, None, :] - p[below][None, :, :], axis=2)
        nearest.append(d.min())
    assert min(nearest) > 0.5 * h
    assert min(nearest) < 2.5 * h


def two_sheets(mass_a, mass_b, speed_a, speed_b, h=0.01, gap=0.05, friction=0.0):
    """Two parallel 0.4 m square cloths 'gap' apart (a above b) of masses mass_a, mass_b,
    a moving down at speed_a and b up at speed_b [m/s]."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=h, restitution=0.0, friction=friction)
    for z, v, mass in ((0.5 * gap, -speed_a, mass_a), (-0.5 * gap, speed_b, mass_b)):
        builder.add_cloth(sb.rectangle((0.4, 0.4), (6, 6), center=(0, 0, z)), mass=mass,
                          stiffness=50.0, damping=0.1, velocity=(0, 0, v))  # fmt: skip
    return builder.finalize()


@pytest.mark.parametrize("integrator", ["symplectic_euler", "implicit_euler"])
def test_a_held_back_sheet_takes_the_velocity_of_its_bounded_step(integrator):
    """The bound holds back two sheets thrown at each other at 30 h per step each (5 h
    apart: it lets each move 1 h), and must not leave them their velocities (they would
    propose the same long step again). The rule (thick.hpp, hold): a held particle's
    velocity changes by its bound's move over dt, less its group's mass-weighted mean
    change. Reference: symmetric sheets (equal masses and speeds: the mean change is 0)
    have after the first step every particle's velocity equal to its displacement over the
    step / dt (backward and symplectic Euler: q = q0 + dt qd), -+10 m/s where they came in
    at -+300 m/s, to round-off; the total momentum stays 0."""
    h, dt = 0.01, 1e-3
    model = two_sheets(0.1, 0.1, 30 * h / dt, 30 * h / dt, h=h)
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    q0 = state.particle_q.copy()
    sim.run(state, 1)
    step = (state.particle_q - q0) / dt
    assert np.abs(step[:, 2]).min() > 9.0  # it was held: 1 h of the 30 h it proposed
    assert np.abs(step[:, 2]).max() < 11.0
    assert np.allclose(state.particle_qd, step, rtol=0.0, atol=1e-9 * 300.0)
    assert np.abs(momentum(model, state)).max() < 1e-12


@pytest.mark.parametrize("integrator", ["symplectic_euler", "midpoint"])
def test_sheets_that_start_beyond_h_and_end_within_it_are_pushed_to_h(integrator):
    """The response must see every pair that ends a step within h, including pairs that
    started it farther than h (the response reads a row only where its particles' moves
    can bring it within h). Two sheets 1.2 h apart thrown at each other at 0.5 h per step
    each: the bound lets them close 0.4 of 1.2 h, to 0.72 h, and the response pushes every
    pair back to h. Reference: after the step the sheets' heights are at least h apart
    everywhere (to 1e-5 h: the pairs' pushes, one after another, leave the sheets a little
    uneven), and they did approach (less than 1.2 h apart)."""
    h, dt = 0.01, 1e-3
    model = two_sheets(0.1, 0.1, 0.5 * h / dt, 0.5 * h / dt, h=h, gap=1.2 * h)
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    sim.run(state, 1)
    (a0, a1), (b0, b1) = model.body_particle_range
    z = state.particle_q[:, 2]
    assert z[a0:a1].min() - z[b0:b1].max() >= h * (1.0 - 1e-5)
    assert z[a0:a1].max() - z[b0:b1].min() < 1.2 * h


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_a_held_back_pair_of_unequal_sheets_conserves_momentum(friction):
    """Sheets of 0.1 kg and 0.3 kg thrown at each other at 400 and 100 m/s (momentum -10
    kg m/s along z): the bound holds them back for several steps and hold() changes their
    velocities. Reference: every velocity change is equal and opposite between a group's
    particles (the group's mean change taken away), so the total momentum stays at its
    start to round-off at every step; after the first step the sheets' relative velocity
    equals their relative displacement over the step / dt (each held pair's relative
    velocity that of its bounded step), to round-off; they never pass each other."""
    h, dt = 0.01, 1e-3
    model = two_sheets(0.1, 0.3, 400.0, 100.0, h=h, friction=friction)
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=dt)
    state = model.state()
    (a0, a1), (b0, b1) = model.body_particle_range
    p0 = momentum(model, state)
    q0 = state.particle_q.copy()
    sim.run(state, 1)
    step = (state.particle_q - q0) / dt
    relative_v = state.particle_qd[a0:a1, 2].mean() - state.particle_qd[b0:b1, 2].mean()
    relative_step = step[a0:a1, 2].mean() - step[b0:b1, 2].mean()
    assert relative_step > -30.0  # held: 2 h of the 50 h the pair proposed
    assert relative_v == pytest.approx(relative_step, rel=1e-9)
    edges = unique_edges(model.tri_indices)
    for _ in range(10):
        assert np.abs(momentum(model, state) - p0).max() < 1e-12
        assert state.particle_q[a0:a1, 2].min() > state.particle_q[b0:b1, 2].max()
        assert len(edge_crossings(state.particle_q, model.tri_indices, edges)) == 0
        sim.run(state, 1)


def test_sheets_rest_a_thickness_apart():
    """Two sheets pushed together slowly (0.2 m/s, restitution 0) end held apart by the
    thickness: their heights differ by h = 0.01 m within the bound's slack (no sheet ever
    nearer than h / 2, and none farther than 2 h at the end)."""
    model = sheets(0.2, thickness=0.01, gap=0.03)
    sim = sb.Simulator(model, integrator="implicit_euler", dt=1e-3)
    state = model.state()
    (a0, a1), (b0, b1) = model.body_particle_range
    for _ in range(20):
        sim.run(state, 10)
        gap = state.particle_q[a0:a1, 2].mean() - state.particle_q[b0:b1, 2].mean()
        assert gap > 0.005
    assert gap < 0.02


# -- a crossing at the start, bad input ----------------------------------------------------
def test_an_initial_crossing_stops_the_run_and_says_where():
    """A sheet through another at the start (a self-intersecting set-up) cannot be
    separated by any bound: the run stops at its first step with Status.CROSSED, naming the
    edge's particle and the triangle it passes through, and leaves the state at the start."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=0.005)
    builder.add_cloth(sb.rectangle((0.4, 0.4), (4, 4)), mass=0.1, stiffness=50.0)
    upright = sb.rectangle((0.4, 0.4), (4, 4)).rotated(
        np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    ).translated((0.013, 0.011, 0.017))
    builder.add_cloth(upright, mass=0.1, stiffness=50.0)
    model = builder.finalize()
    assert len(edge_crossings(model.particle_q, model.tri_indices,
                              unique_edges(model.tri_indices)))  # fmt: skip
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-3)
    state = model.state()
    with pytest.raises(sb.SimulationError, match=r"crossed a surface at step 0 .*particle \d+ "
                       r"passes through triangle \d+") as info:  # fmt: skip
        sim.run(state, 5)
    assert info.value.particle >= 0
    assert np.array_equal(state.particle_q, model.particle_q)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"thickness": 0.0}, "thickness must be > 0"),
        ({"thickness": -1.0}, "thickness must be > 0"),
        ({"thickness": float("nan")}, "thickness must be finite"),
        ({"thickness": "thin"}, "thickness must be a number"),
        ({"self_contact": "yes"}, "self_contact must be True or False"),
        ({"mode": "bounding", "self_contact": True}, "need soft contact mode 'surface'"),
        ({"mode": "none", "thickness": 0.01}, "need soft contact mode 'surface'"),
        ({"thickness": 0.02, "margin": 0.01}, "margin must be >= the thickness"),
    ],
)
def test_bad_self_contact_settings_are_named(kwargs, message):
    """Bad input to set_soft_contact: a thickness <= 0 or not a finite number, a
    self_contact that is not a bool, self_contact or thickness with a mode other than
    'surface', a margin below the thickness: a ValueError naming the setting."""
    kwargs = {"mode": "surface", **kwargs}
    with pytest.raises(ValueError, match=message):
        sb.ModelBuilder().set_soft_contact(**kwargs)


@pytest.mark.parametrize(
    ("contact", "message"),
    [
        ('thickness = 0', "contact.thickness"),
        ('thickness = -0.01', "contact.thickness"),
        ('mode = "bounding"\nself_contact = true', "contact.self_contact"),
        ('mode = "none"\nthickness = 0.01', "contact.thickness"),
        ('self_contact = 1', "contact.self_contact"),
        ('thickness = 0.02\nmargin = 0.01', "contact.margin"),
    ],
)
def test_bad_scene_contact_keys_are_one_line(tmp_path, contact, message):
    """The scene file's [contact] self_contact and thickness keys are checked like every
    other key: one line naming the key, non-zero exit, no output folder."""
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.format(contact=contact))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "softbody.cli", "run", str(scene), "--out",
                        str(out)], capture_output=True, text=True)  # fmt: skip
    assert r.returncode != 0
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "Traceback" not in r.stderr
    assert not out.exists()


SCENE = """
[simulation]
duration = 0.01
[contact]
{contact}
[[bodies]]
mesh = {{ shape = "icosphere", subdivisions = 1 }}
mass = 1.0
stiffness = 100.0
gas = 100.0
"""


def test_scene_self_contact_runs(tmp_path):
    """A scene with [contact] self_contact = true and a thickness builds the model with
    them (the loader passes the keys through to set_soft_contact)."""
    from softbody.scenes.loader import build_scene

    data = tomllib.loads(SCENE.format(contact="self_contact = true\nthickness = 0.02"))
    scene = build_scene("s", data)
    assert scene.model.soft_self_contact == 1
    assert scene.model.contact_thickness == 0.02
