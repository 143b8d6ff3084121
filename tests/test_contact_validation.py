"""Issue 32's validations of surfaces with a thickness (core/collision/thick.hpp): cloth
dropped into a pile, two balloons pressed together, the contact force of a body resting on
a soft body, self-contact in every solver; and the independent checks they use
(softbody.collision.crossings)."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
from trimesh.triangles import closest_point

import softbody as sb
from softbody.collision import rotation_about
from softbody.collision.crossings import candidate_pairs, edge_crossings, vertex_triangle_gaps
from softbody.diagnostics import body_pressure, body_volume
from softbody.mesh.topology import unique_edges
from test_self_contact import run_sampled, vacuum_ball


# -- the checks' own references ------------------------------------------------------------
def test_candidate_pairs_of_two_sets_of_boxes_of_different_extents():
    """candidate_pairs against a test of every pair: two seeded sets of boxes that do not
    start at the same grid cell (small boxes scattered over a wide range, large ones over a
    narrow one) give exactly the meeting pairs (their grid keys share one origin; each set
    shifted to its own first cell would miss pairs)."""
    rng = np.random.default_rng(11)
    a = rng.uniform(-3.0, 3.0, size=(300, 3))
    b = rng.uniform(0.5, 2.0, size=(80, 3))
    alo, ahi = a, a + rng.uniform(0.0, 0.3, size=a.shape)
    blo, bhi = b, b + rng.uniform(0.2, 1.0, size=b.shape)
    meet = np.all((alo[:, None] <= bhi[None]) & (blo[None] <= ahi[:, None]), axis=2)
    brute = set(zip(*np.nonzero(meet), strict=True))
    found = set(zip(*(x.tolist() for x in candidate_pairs(alo, ahi, blo, bhi)), strict=True))
    assert len(brute) > 20
    assert found == brute


def test_vertex_triangle_gaps_against_trimesh():
    """vertex_triangle_gaps against trimesh's closest point on a triangle, taken over every
    triangle (no grid): on a seeded random soup, each vertex's distance to the nearest
    triangle not touching it, within the radius, agrees to round-off (inf where none is
    that near), for all vertices and for a subset measured against part of the soup."""
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 3))
    tri = rng.integers(0, 200, size=(150, 3))
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])]
    radius = 0.8
    for vertices, part in ((np.arange(200), tri), (np.arange(50, 120), tri[:60])):
        expected = np.full(len(vertices), np.inf)
        for k, v in enumerate(vertices):
            others = part[~np.any(part == v, axis=1)]
            d = np.linalg.norm(closest_point(q[others], np.repeat(q[v][None], len(others), 0))
                               - q[v], axis=1)  # fmt: skip
            d = d[d <= radius]
            expected[k] = d.min() if len(d) else np.inf
        got = vertex_triangle_gaps(q, part, vertices, radius=radius)
        assert np.isfinite(expected).sum() > 0.5 * len(vertices)
        assert np.array_equal(np.isfinite(got), np.isfinite(expected))
        assert np.allclose(got[np.isfinite(got)], expected[np.isfinite(expected)], atol=1e-12)


# -- cloth dropped into a pile -------------------------------------------------------------
G = 9.81
PILE_H = 0.006  # [m] the cloth's thickness: 0.18 of its 0.033 m edges


def pile_model(self_contact: bool = True):
    """A 0.2 x 1.2 m strip of cloth (6 x 36 squares, 259 vertices, 0.1 kg) standing on its
    short edge 2 cm above the ground, leaning 0.1 rad, with hardly any bending stiffness:
    it lands and folds onto itself into a pile."""
    builder = sb.ModelBuilder()
    if self_contact:
        builder.set_soft_contact("surface", self_contact=True, thickness=PILE_H,
                                 restitution=0.0, friction=0.3)  # fmt: skip
    lean = rotation_about((1, 0, 0), 0.1)
    strip = sb.rectangle((0.2, 1.2), (6, 36)).rotated(lean)
    strip = strip.translated((0.0, 0.02 - strip.vertices[:, 1].min(), 0.0))
    builder.add_cloth(strip, mass=0.1, stiffness=200.0, damping=0.05, bend_stiffness=0.002)
    builder.add_collider(sb.ColliderPlane(restitution=0.0, friction=0.5))
    return builder.finalize()


def layer_counts(q: np.ndarray, tri: np.ndarray, spacing: float = 0.01) -> np.ndarray:
    """How many triangles each vertical line of a grid (``spacing`` [m] apart) over the
    pile passes through: the number of layers of cloth there. Shape (lines,)."""
    xz = q[:, [0, 2]]
    lo, hi = xz.min(axis=0), xz.max(axis=0)
    grid = np.meshgrid(
        *(np.arange(a, b, spacing) + spacing / 2 for a, b in zip(lo, hi, strict=True))
    )
    p = np.stack([g.ravel() for g in grid], axis=1)[:, None]  # (lines, 1, 2)
    a, b, c = xz[tri[:, 0]], xz[tri[:, 1]], xz[tri[:, 2]]

    def side(u, v):  # the 2D cross product (v - u) x (p - u), (lines, triangles)
        d, r = v - u, p - u
        return d[:, 0] * r[..., 1] - d[:, 1] * r[..., 0]

    w = [side(b, c), side(c, a), side(a, b)]
    inside = ((w[0] > 0) & (w[1] > 0) & (w[2] > 0)) | ((w[0] < 0) & (w[1] < 0) & (w[2] < 0))
    return inside.sum(axis=1)


def drop_pile(model, integrator: str, dt: float, duration: float = 2.0, every: float = 0.05):
    """Runs the pile, checking every `every` s: (state, most crossings at a sampled frame,
    lowest height of a vertex [m])."""
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    edges = unique_edges(model.tri_indices)
    most, lowest = 0, np.inf
    while state.time < duration - 1e-9:
        sim.run(state, round(every / dt))
        most = max(most, len(edge_crossings(state.particle_q, model.tri_indices, edges)))
        lowest = min(lowest, state.particle_q[:, 1].min())
    return state, most, lowest


PILE_SOLVERS = [("symplectic_euler", 2.5e-4), ("implicit_euler", 2.5e-4), ("xpbd", 2e-3)]


@pytest.mark.parametrize(("integrator", "dt"), PILE_SOLVERS)
def test_cloth_dropped_into_a_pile(integrator, dt):
    """Cloth dropped into a pile (issue 32): a strip standing on the ground falls and folds
    onto itself, in an explicit solver, implicit Euler and xpbd. References: at every frame
    sampled each 0.05 s the independent segment-triangle test (edge_crossings) finds no
    cloth edge through a non-adjacent triangle, and no vertex is below the ground; at 2 s
    a vertical line passes through 4 or more layers somewhere (it folded onto itself at
    least three times), every vertex is at least h from each triangle not touching it less
    2 % (the response puts each pair nearer than h at h at every step's end; 2 % for pairs
    sharing particles, pushed apart one after another in one pass; measured 0.45 % below h
    at most), and the pile rests: its kinetic energy is under 1e-4 of the potential energy
    its fall released (m g times its centre's drop; measured 3e-6 to 2e-5 in the explicit
    solver and xpbd, 4e-5 in implicit Euler, where it varies by 2x with the order the
    contact stage visits its pairs in: the fold is chaotic). Without self-contact the same
    run crosses itself (the check bites). The step is 2.5e-4 s in the solvers whose contact
    stage runs once a step (implicit Euler at 1e-3 s piles without a crossing too, since
    the stage and the ground collider run in turn: measured, not tested here)."""
    model = pile_model()
    state, most, lowest = drop_pile(model, integrator, dt)
    q = state.particle_q
    assert most == 0
    assert lowest >= -1e-9
    assert layer_counts(q, model.tri_indices).max() >= 4
    gaps = vertex_triangle_gaps(q, model.tri_indices, radius=2 * PILE_H)
    assert gaps.min() >= 0.98 * PILE_H
    kinetic = 0.5 * np.sum(model.particle_mass * np.sum(state.particle_qd**2, axis=1))
    mass = model.particle_mass.sum()
    drop = (model.particle_mass @ (model.particle_q[:, 1] - q[:, 1])) / mass
    assert drop > 0.5
    assert kinetic < 1e-4 * mass * G * drop
    _, crossed, _ = drop_pile(pile_model(self_contact=False), integrator, dt)
    assert crossed > 0


# -- a collider after the contact stage ----------------------------------------------------
FACE_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # xy plane to xz


def sheet_onto_sheet(ground: bool, speed: float = 30.0, h: float = 0.01, collider=None):
    """A 0.4 m square sheet lying at y = 0 (on the ground plane, with ``ground``) and a
    second one 5 h above it falling onto it at ``speed`` [m/s] (no gravity, frictionless);
    ``collider``: one more rigid collider."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=h, restitution=0.0, friction=0.0)
    sheet = sb.rectangle((0.4, 0.4), (6, 6)).rotated(FACE_UP)
    builder.add_cloth(sheet, mass=0.1, stiffness=50.0)
    builder.add_cloth(sheet.translated((0.013, 5 * h, 0.011)), mass=0.1, stiffness=50.0,
                      velocity=(0.0, -speed, 0.0))  # fmt: skip
    if ground:
        builder.add_collider(sb.ColliderPlane(restitution=0.0, friction=0.0))
    if collider is not None:
        builder.add_collider(collider)
    return builder.finalize()


@pytest.mark.parametrize("ground", [False, True])
def test_a_sheet_falling_onto_a_sheet_on_the_ground_stays_apart(ground):
    """A sheet falling at 3 h per step (dt 1 ms) onto a sheet lying at y = 0: after every
    step of 20 each vertex of the falling sheet is at least h / 2 from the lower sheet's
    triangles (the stage's bound keeps a pair's distance above 0.6 of its start, its
    response pushes it to h). Free, the lower sheet is pushed along (measured >= 0.97 h).
    On a ground plane too (measured h from the third step): with rigid colliders the stage
    takes no common translation T and runs again after them, holding the particles they
    caught. When the colliders acted after a stage with T (the mean fall of the two
    sheets, 15 mm), its bound carried the resting sheet into the ground and the ground
    lifted it back, unbounded: the falling sheet lay on it (both at y = 0) after the third
    step."""
    h = 0.01
    model = sheet_onto_sheet(ground, h=h)
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-3)
    state = model.state()
    (_, a1), (b0, b1) = model.body_particle_range
    lower = model.tri_indices[: len(model.tri_indices) // 2]
    assert np.all(lower < a1)
    for _ in range(20):
        sim.run(state, 1)
        gaps = vertex_triangle_gaps(state.particle_q, lower, np.arange(b0, b1), radius=2 * h)
        assert gaps.min() >= 0.5 * h


def test_a_ball_falling_onto_a_sheet_on_the_ground_stays_a_thickness_above_it():
    """A gas ball (162 vertices, 0.15 m, 1 kg) falling at 6 m/s onto a 0.8 m sheet (0.2 kg)
    lying on a ground plane, no gravity, frictionless, symplectic Euler at 1 ms: after every
    step of 80 (first contact at the fourth, the ball pressed into the sheet on the ground
    from the ninth) each ball vertex is at least 0.9 h from the sheet's triangles. The
    stage's response puts its pairs h apart, and the colliders after it move only the
    particles they catch (measured 0.98 h, as without the ground). Near a collider the stage
    runs without the common translation T (loop::thick_with_colliders): one with T there
    (the ball's fall, most of the mass) has its bound carry the resting sheet into the
    ground behind the ball every step, the ground put it back, and the ball end nearer
    (measured 0.80 h)."""
    h = 0.01
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", thickness=h, restitution=0.0, friction=0.0)
    builder.add_cloth(sb.rectangle((0.8, 0.8), (12, 12)).rotated(FACE_UP), mass=0.2,
                      stiffness=50.0)  # fmt: skip
    builder.add_soft_body(sb.icosphere(2, radius=0.15, center=(0.0, 0.2, 0.0)), mass=1.0,
                          stiffness=500.0, damping=0.5, gas=sb.Gas.isothermal(50.0),
                          velocity=(0.0, -6.0, 0.0))  # fmt: skip
    builder.add_collider(sb.ColliderPlane(restitution=0.0, friction=0.0))
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-3)
    state = model.state()
    (_, a1), (b0, b1) = model.body_particle_range
    sheet = model.tri_indices[np.all(model.tri_indices < a1, axis=1)]
    for _ in range(80):
        sim.run(state, 1)
        gaps = vertex_triangle_gaps(state.particle_q, sheet, np.arange(b0, b1), radius=2 * h)
        assert gaps.min() >= 0.9 * h
    assert state.particle_q[b0:b1, 1].min() < 2 * h  # it lies on the sheet (measured 1.02 h)


FAR_COLLIDERS = {
    "plane": sb.ColliderPlane(point=(0.0, -1.0, 0.0)),
    "sphere": sb.ColliderSphere(center=(0.0, -1.0, 0.0), radius=0.5),
    "box": sb.ColliderBox(
        center=(0.9, 0.0, 0.0),
        half_extents=(0.4, 0.4, 0.4),
        rotation=rotation_about((0.0, 1.0, 0.0), 0.3),
    ),
    "container": sb.ColliderBox(half_extents=(1.0, 1.0, 1.0), container=True),
    "mesh": sb.ColliderMesh(sb.box((0.4, 0.4, 0.4)), center=(0.0, 0.0, -0.9)),
}


@pytest.mark.parametrize("kind", sorted(FAR_COLLIDERS))
def test_a_collider_far_from_the_sheets_leaves_their_steps_bit_equal(kind):
    """The sheet falling at 3 h per step onto the free one (the case above, without the
    ground), with a collider of each kind that none of their paths comes near (a plane 1 m
    below, a sphere, a turned solid box, a mesh box beside them, a container 1 m around):
    every one of 20 steps ends bit-equal, positions and velocities, to the run without
    it (loop::thick_with_colliders runs the stage with the common translation T where the
    box of the step's paths, grown by h / 2, is apart from every collider and a stage
    without T would sweep, 30 mm a step here: then the colliders catch nothing and the step
    is the no-collider path). Without T the stage's
    bound holds the sheets back toward their start instead of toward the start plus T:
    different positions (measured: from the second step)."""
    free = sheet_onto_sheet(False)
    walled = sheet_onto_sheet(False, collider=FAR_COLLIDERS[kind])
    states = [free.state(), walled.state()]
    sims = [sb.Simulator(mod, integrator="symplectic_euler", dt=1e-3) for mod in (free, walled)]
    for _ in range(20):
        for sim, state in zip(sims, states, strict=True):
            sim.run(state, 1)
        np.testing.assert_array_equal(states[1].particle_q, states[0].particle_q)
        np.testing.assert_array_equal(states[1].particle_qd, states[0].particle_qd)


def test_a_ball_with_self_contact_falls_as_without_the_ground_until_near_it():
    """A 162-vertex gas ball with self-contact (h 1 cm) dropped 1 m onto a ground plane, by
    implicit Euler at 1/60 s: each step whose paths (grown by h / 2) stay above the ground
    ends bit-equal to the same run without the ground (the stage takes the common
    translation T there, as without colliders, where the step's motion would make it sweep
    without T; in the first steps, of small motion, it keeps a list either way, and its
    bound holds nothing back); once the ball reaches it, the ground holds every vertex at
    y >= 0 and the runs part."""

    def ball(ground):
        builder = sb.ModelBuilder()
        builder.set_soft_contact("surface", thickness=0.01, self_contact=True)
        builder.add_soft_body(
            sb.icosphere(2, radius=0.5, center=(0.0, 1.5, 0.0)),
            mass=1.0,
            stiffness=500.0,
            damping=0.5,
            gas=sb.Gas.isothermal(150.0),
        )
        if ground:
            builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
        return builder.finalize()

    models = [ball(False), ball(True)]
    states = [mod.state() for mod in models]
    sims = [sb.Simulator(mod, integrator="implicit_euler", dt=1 / 60) for mod in models]
    far_steps, parted = 0, False
    for _ in range(40):
        low = min(state.particle_q[:, 1].min() for state in states)
        for sim, state in zip(sims, states, strict=True):
            sim.run(state, 1)
        low = min(low, states[0].particle_q[:, 1].min())
        same = np.array_equal(states[1].particle_q, states[0].particle_q)
        if low > 0.02:  # the step's paths stay above the ground by more than h (they are
            assert same  # straight, and the stage's moves within h / 2 of them)
            far_steps += 1
        parted |= not same
        assert states[1].particle_q[:, 1].min() >= 0.0
    assert far_steps >= 15
    assert parted


# -- two balloons pressed together ---------------------------------------------------------
BALLOON_R, BALLOON_H, BALLOON_NRT = 0.25, 0.01, 50.0  # [m], [m], [J]
BALLOON_MASS = (1.0, 0.6)  # [kg] the lower, the upper


def balloon_stack():
    """Two gas-filled balls (162 vertices each, radius 0.25 m, isothermal nRT = 50 J),
    the lower (1 kg) on the ground, the upper (0.6 kg) on it, surface contacts with a
    thickness h = 1 cm between them; four frictionless walls 1.2 radii from the axis keep
    the upper one from rolling off (a ball on a ball is unstable)."""
    builder = sb.ModelBuilder()
    builder.set_soft_contact("surface", thickness=BALLOON_H, restitution=0.0, friction=0.5)
    centres = (BALLOON_R + 0.002, 3 * BALLOON_R + BALLOON_H + 0.004)
    for y, mass in zip(centres, BALLOON_MASS, strict=True):
        builder.add_soft_body(sb.icosphere(2, radius=BALLOON_R, center=(0.0, y, 0.0)),
                              mass=mass, stiffness=800.0, damping=3.0,
                              gas=sb.Gas.isothermal(BALLOON_NRT))  # fmt: skip
    builder.add_collider(sb.ColliderPlane(restitution=0.0, friction=0.5))
    for normal in np.array([(1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1)], dtype=float):
        wall = sb.ColliderPlane(point=-1.2 * BALLOON_R * normal, normal=normal, restitution=0.0,
                                friction=0.0)  # fmt: skip
        builder.add_collider(wall)
    return builder.finalize()


def body_momentum(model, state, body: int) -> np.ndarray:
    """Momentum of one body [kg m/s], shape (3,)."""
    a, b = model.body_particle_range[body]
    return model.particle_mass[a:b] @ state.particle_qd[a:b]


@pytest.mark.parametrize(("integrator", "dt"), [("symplectic_euler", 2.5e-4),
                                                ("implicit_euler", 2e-3)])  # fmt: skip
def test_two_balloons_pressed_together(integrator, dt):
    """Two balloons pressed together by gravity, one stacked on the other on the ground
    (issue 32; also the contact force of a body resting on a soft body: the upper balloon
    rests on the lower one). References, over 6 s of settling sampled every 0.1 s: no edge
    through a triangle (edge_crossings), and every vertex of each balloon at least h less
    5 % from the other's triangles (the response puts each pair at h at every step's end;
    measured 2e-5 h below it), and touching (under 1.05 h, or under 1.55 h in implicit
    Euler, whose solve holds contacts in the band below its penalty's zero at 1.5 h). At
    rest, over 1 s: the ground's impulse per second is the
    total weight (M_1 + M_2) g, and the contact stage's vertical impulse on the upper
    balloon, from its momentum balance (its momentum change less its weight's impulse; the
    frictionless walls push only sideways), is its weight M_2 g, both within 1 % (the
    stack's residual rocking; measured under 0.1 %); the impulse on the lower balloon is
    its opposite (Newton's third law, to the implicit solve's tolerance). The gas law at
    the deformed volumes: p V = nRT for each, both volumes positive, and the lower balloon,
    squeezed by both weights, is the smaller and at the higher pressure."""
    model = balloon_stack()
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    tri, edges = model.tri_indices, unique_edges(model.tri_indices)
    half = len(tri) // 2  # body 0's triangles, then body 1's
    (a0, a1), (b0, b1) = model.body_particle_range
    per = round(0.1 / dt)
    while state.time < 6.0 - 1e-9:
        sim.run(state, per)
        q = state.particle_q
        assert len(edge_crossings(q, tri, edges)) == 0
        upper_gap = vertex_triangle_gaps(q, tri[:half], np.arange(b0, b1), radius=2 * BALLOON_H)
        lower_gap = vertex_triangle_gaps(q, tri[half:], np.arange(a0, a1), radius=2 * BALLOON_H)
        assert min(upper_gap.min(), lower_gap.min()) >= 0.95 * BALLOON_H
    # they touch: at h after the stage's response, or, in the implicit solvers, within the
    # band their solve holds contacts in (the penalty's zero at 1.5 h, thick_system.hpp)
    band = 1.55 if integrator == "implicit_euler" else 1.05
    assert upper_gap.min() < band * BALLOON_H
    p_lower, p_upper = body_momentum(model, state, 0), body_momentum(model, state, 1)
    steps = round(1.0 / dt)
    sim.run(state, steps)  # the colliders' impulses: those of this call
    window = steps * dt
    m_lower, m_upper = BALLOON_MASS
    ground = -state.collider_impulse[0, 1] / window  # [N]
    assert np.abs(state.collider_impulse[1:, 1]).max() < 1e-9
    assert ground == pytest.approx((m_lower + m_upper) * G, rel=0.01)
    on_upper = body_momentum(model, state, 1)[1] - p_upper[1] + m_upper * G * window
    on_lower = (body_momentum(model, state, 0)[1] - p_lower[1] + m_lower * G * window
                + state.collider_impulse[:, 1].sum())  # fmt: skip
    assert on_upper / window == pytest.approx(m_upper * G, rel=0.01)
    assert abs(on_lower + on_upper) < 1e-5 * m_upper * G * window
    volume, pressure = body_volume(model, state), body_pressure(model, state)
    assert pressure * volume == pytest.approx([BALLOON_NRT, BALLOON_NRT], rel=1e-9)
    assert 0 < volume[0] < volume[1]
    assert pressure[0] > pressure[1]


# -- self-contact in every solver ----------------------------------------------------------
SOLVER_STEPS = {"euler": 5e-4, "midpoint": 1.2e-3, "rk4": 1.2e-3, "symplectic_euler": 1.2e-3,
                "velocity_verlet": 1.2e-3, "implicit_euler": 1 / 240, "bdf2": 1 / 240,
                "projective": 1 / 240, "xpbd": 1 / 240}  # fmt: skip


def test_every_solver_is_listed():
    """The solvers below are every member of sb.Integrator."""
    assert set(SOLVER_STEPS) == {m.name.lower() for m in sb.Integrator}


@pytest.mark.parametrize("integrator", SOLVER_STEPS)
def test_vacuum_packed_ball_in_every_solver(integrator):
    """Self-contact in every solver: the vacuum-packed ball of test_self_contact.py at 162
    vertices (its gas drawn down to 2 % under a 500 Pa ambient pressure, h = 0.2 x the
    median edge) folds without passing through itself. Reference: edge_crossings finds no
    edge through a non-adjacent triangle at any frame sampled every 0.05 s over 0.6 s, the
    volume stays positive and ends under a third of the start (measured 7-9 %); without
    self-contact the same run crosses itself (the check bites in each solver). Explicit
    Euler runs above its stability estimate and says so (it amplifies undamped vibration at
    any step; the check is of crossings, not accuracy). (The sheets of test_self_contact.py
    run in every solver too, but as two bodies.)"""
    dt = SOLVER_STEPS[integrator]
    model = vacuum_ball(2)
    v0 = body_volume(model, model.state())[0]
    unstable = integrator == "euler"
    with pytest.warns(sb.StabilityWarning) if unstable else contextlib.nullcontext():
        times, volumes, crossings = run_sampled(model, integrator, dt, 0.6)
    assert crossings.max() == 0, f"crossings at t = {times[crossings > 0]}"
    assert volumes.min() > 0
    assert volumes[-1] < v0 / 3
    with pytest.warns(sb.StabilityWarning) if unstable else contextlib.nullcontext():
        _, _, without = run_sampled(vacuum_ball(2, self_contact=False), integrator, dt, 0.6)
    assert without.max() > 0
