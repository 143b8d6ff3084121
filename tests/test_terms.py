"""Each term's energy and stiffness-bound pieces, computed in its own file of the compiled
core (``core/terms/*.hpp``; ``softbody._core.eval_energies`` and ``stiffness_bounds``).

Energies against the NumPy reference (``softbody.reference``), per term and per body, on
every instruction set: the two codes round each product and add in another order, so
they differ by at most a few units of round-off eps = 2^-52 times the sum of the
magnitudes of what was added (``ULPS`` eps sum |terms|, as in test_reference.py), the
magnitudes taken where a difference cancels (L - L0 of a spring, P - P_a of a gas). And
``diagnostics.energies`` against the composition of the reference it used before.

Each conservative force is minus the gradient of the core's energy: -dE/dx . p from
central differences along random p equals f . p. Central differences err by O(h^2): the
error at h/2 is a quarter of that at h, so |D(h/2) - exact| <= |D(h) - D(h/2)| / 3 to
leading order; twice that is allowed, plus the quotient's round-off 64 eps |E| / h.

The bound pieces against the NumPy formulas ``stability.stiffest_mode`` used before they
moved into the core (``_numpy_bounds``, kept here as the oracle), and the Gershgorin part
of ``stiffest_mode`` against their composition.
"""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from softbody import _core, core
from softbody import reference as ref
from softbody.core import core_model
from softbody.reference import attachments, bending, external, gas, gravity, membrane, springs
from softbody.reference import volume as rvolume
from softbody.sim.control import control_data
from softbody.stability import stiffest_mode
from trajectory_cases import every_term_model

EPS = np.finfo(float).eps
#: Units of round-off allowed per unit of summed magnitude (module docstring).
ULPS = 16.0


# -- models ------------------------------------------------------------------------------
def _gas_laws() -> tuple[sb.Model, sb.Control]:
    """Three closed bodies of the exact volume, one per gas law, each with an ambient
    pressure (the isothermal one with a schedule and masses by area, so a spring's two
    ends differ; the fixed-pressure one with material bending); a user's spring between
    two bodies, a free particle on a spring with an attachment, a body's particle attached,
    a grab."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.3), mass=1.0, stiffness=400.0, damping=0.5,
                    gas=sb.Gas.isothermal(40.0, ambient_pressure=20.0,
                                          schedule=[(0.0, 30.0), (0.05, 50.0)]),
                    bend_stiffness=20.0, mass_distribution="area")  # fmt: skip
    b.add_soft_body(sb.icosphere(1, radius=0.25, center=(0.8, 0.1, 0.0)), mass=0.5,
                    stiffness=300.0, damping=0.3,
                    gas=sb.Gas.fixed_pressure(300.0, ambient_pressure=120.0),
                    bending=sb.Bending(0.05))  # fmt: skip
    b.add_soft_body(sb.icosphere(2, radius=0.25, center=(0.0, 0.9, 0.0)), mass=0.5,
                    stiffness=250.0, damping=0.2,
                    gas=sb.Gas.adiabatic(35.0, gamma=1.4, reference_volume=0.1,
                                         ambient_pressure=8.0))  # fmt: skip
    free = b.add_particle((0.3, 0.6, 0.1), mass=0.05)
    b.add_spring(0, 170, stiffness=30.0, damping=0.2, rest_length=0.5)
    b.add_spring(free, 3, stiffness=20.0, damping=0.1, rest_length=0.4)
    b.add_attachment(free, anchor=(0.3, 1.5, 0.1), stiffness=40.0, damping=0.5)
    b.add_attachment(200, anchor=(0.0, 1.5, 0.0), stiffness=25.0, rest_length=0.1)
    model = b.finalize()
    control = model.control()
    control.grab_particle = 40
    control.grab_target = np.array([0.5, 0.9, 0.0])
    control.grab_stiffness = 30.0
    return model, control


def _cloth() -> tuple[sb.Model, sb.Control | None]:
    """An open surface with a fixed-pressure gust (a schedule), pinned corners and
    material bending (a 0.2 mm film of E = 2 GPa), and a pure damper (k = 0, c > 0)
    between two free particles."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_cloth(sb.rectangle((1.0, 0.8), (10, 8)), mass=0.3, stiffness=200.0, damping=0.2,
                pressure=sb.Gas.fixed_pressure(2.0, schedule=[(0.0, 0.0), (0.1, 4.0)]),
                pinned=[0, 10], bend_stiffness=5.0,
                bending=sb.Bending.from_material(2e9, 0.3, 2e-4))  # fmt: skip
    i = b.add_particle((0.0, 1.0, 0.0), mass=0.1)
    j = b.add_particle((0.5, 1.0, 0.0), mass=0.2)
    b.add_spring(i, j, stiffness=0.0, damping=2.0)
    return b.finalize(), None


def _membranes() -> tuple[sb.Model, sb.Control]:
    """Membrane bodies, one per material: a neo-Hookean balloon without springs, a
    Mooney-Rivlin one with edge springs beside it, a StVK one with a damped neo-Hookean
    layer on half its faces, and a StVK cloth; an attachment and a grab."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.3), mass=0.2, gas=sb.Gas.isothermal(40.0),
                    membrane=sb.Membrane.neo_hookean(2e5, 1e-3))  # fmt: skip
    b.add_soft_body(sb.icosphere(1, radius=0.25, center=(0.8, 0.0, 0.0)), mass=0.2,
                    stiffness=50.0, damping=0.1, gas=sb.Gas.fixed_pressure(300.0),
                    membrane=sb.Membrane.mooney_rivlin(1e5, 3e4, 5e-4))  # fmt: skip
    half = np.arange(0, 80, 2)
    b.add_soft_body(sb.icosphere(1, radius=0.25, center=(0.0, 0.9, 0.0)),
                    gas=sb.Gas.adiabatic(35.0, ambient_pressure=8.0), density=1000.0,
                    membrane=[(sb.Membrane.stvk(1e6, 0.3, 2e-4), None),
                              (sb.Membrane.neo_hookean(5e5, 1e-4, damping=0.01), half)],
                    )  # fmt: skip
    b.add_cloth(sb.rectangle((1.0, 0.8), (6, 5)), mass=0.1, pinned=[0, 6],
                membrane=sb.Membrane.stvk(5e5, 0.4, 3e-4))  # fmt: skip
    b.add_attachment(5, anchor=(0.0, 1.0, 0.0), stiffness=40.0, damping=0.5)
    model = b.finalize()
    control = model.control()
    control.grab_particle = 50
    control.grab_target = np.array([0.5, 0.9, 0.0])
    control.grab_stiffness = 30.0
    return model, control


MODELS = {"every-term": every_term_model, "gas-laws": _gas_laws, "cloth": _cloth,
          "membranes": _membranes}  # fmt: skip
#: The models whose stiffness bounds the NumPy formulas below cover (springs, attachments,
#: gas); the membrane's bound is tested in test_membrane.py.
BOUND_MODELS = ["every-term", "gas-laws", "cloth"]
_BUILT: dict = {}


def _inputs(name: str, seed: int = 3):
    """(model, control, control arrays, t [s], q (N, 3), qd (N, 3)): each body scaled by
    1.05 about its centre and every particle moved by up to 1 cm, so springs are both
    stretched and compressed; t = 0.03 s is inside the schedules."""
    if name not in _BUILT:
        _BUILT[name] = MODELS[name]()
    model, control = _BUILT[name]
    rng = np.random.default_rng(seed)
    q = model.particle_q.copy()
    for p0, p1 in model.body_particle_range:
        c = q[p0:p1].mean(axis=0)
        q[p0:p1] = c + 1.05 * (q[p0:p1] - c)
    q += rng.uniform(-0.01, 0.01, q.shape)
    qd = rng.normal(0.0, 0.3, q.shape)
    return model, control, ref.control_arrays(model, control), 0.03, q, qd


@pytest.fixture(params=core.simd_paths())
def simd(request):
    """Each instruction set this CPU runs, restored afterwards."""
    before = core.simd_path()
    core.use_simd(request.param)
    yield request.param
    core.use_simd(before)


def _per_body(values: np.ndarray, owner: np.ndarray, bodies: int) -> np.ndarray:
    keep = owner >= 0
    return np.bincount(owner[keep], weights=values[keep], minlength=bodies)


def _close(actual, expected, scale, what):
    """|actual - expected| <= ULPS eps scale, element-wise."""
    actual, expected = np.atleast_1d(actual), np.atleast_1d(expected)
    error = np.abs(actual - expected)
    tol = ULPS * EPS * np.broadcast_to(scale, error.shape)
    assert np.all(error <= tol), f"{what}: |difference| {error.max():.3g} > {tol.max():.3g}"


# -- energies ----------------------------------------------------------------------------
def _reference_energies(model, data, t, q, volume):
    """Per term (total, per body (B,), round-off scale of the total, of each body's): the
    reference's energies, the gas at the given volumes (B,) [m^3]."""
    bodies = model.body_count
    pb = model.particle_body
    out = {}
    # gravity: each -m g . x rounds at the size m |g| |x|
    e = gravity.energies(model, q)
    size = model.particle_mass * np.linalg.norm(model.gravity) * np.linalg.norm(q, axis=1)
    out["gravity"] = (e.sum(), _per_body(e, pb, bodies), size.sum(), _per_body(size, pb, bodies))
    # springs and attachments: 1/2 k (L - L0)^2 with L rounded at eps L: k |L - L0| L each
    length = springs.lengths(model, q)
    e = springs.energies(model, q)
    size = e + model.spring_stiffness * np.abs(length - model.spring_rest_length) * length
    owner = model.spring_body
    out["springs"] = (e.sum(), _per_body(e, owner, bodies), size.sum(),
                      _per_body(size, owner, bodies))  # fmt: skip
    a = model.attachment_particle
    la = np.linalg.norm(np.asarray(data.attachment_anchor) - q[a], axis=1)
    e = attachments.energies(model, data, q)
    size = e + model.attachment_stiffness * np.abs(la - model.attachment_rest_length) * la
    out["attachments"] = (e.sum(), _per_body(e, pb[a], bodies), size.sum(),
                          _per_body(size, pb[a], bodies))  # fmt: skip
    # gas: E(V) + P_a V, each part and the driving value rounded once or twice
    e = gas.energies(model, data, t, volume)
    value = gas.driving_values(model, data, t)
    parts = gas.law_energy(model.body_gas_law, value, model.body_gas_gamma,
                           model.body_gas_reference_volume, 0.0 * value, volume)  # fmt: skip
    size = np.where(model.body_closed == 1, np.abs(parts) + np.abs(value)
                    + model.body_ambient_pressure * np.abs(volume), 0.0)  # fmt: skip
    out["gas"] = (e.sum(), e, size.sum(), size)
    # bending: k (theta - theta0)^2, theta rounded at about eps (|theta| + 1) (an atan2 of
    # products of differences): k |theta - theta0| (|theta| + 1) each
    theta, _, _ = bending.angles_and_gradients(model, q)
    e = bending.energies(model, q)
    size = e + model.bending_stiffness * np.abs(bending.excess(model, theta)) * (np.abs(theta) + 1)
    owner = model.bending_body
    out["bending"] = (e.sum(), _per_body(e, owner, bodies), size.sum(),
                      _per_body(size, owner, bodies))  # fmt: skip
    # membranes: A0 H W(C), W's terms (each of size |parameter| times the invariants,
    # which cancel to W) rounded at their own size
    f = membrane.deformation(model, q)
    c = np.einsum("tkb,tkc->tbc", f, f)
    tr = c[:, 0, 0] + c[:, 1, 1]
    det = c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] ** 2
    p0, p1 = np.abs(model.membrane_params).T
    size = model.membrane_rest_area * model.membrane_thickness * (p0 + p1) * (
        (tr + 2.0) ** 2 + 1.0 / det + det + tr / det + 3.0
    )
    e = membrane.energies(model, q)
    owner = model.membrane_body
    out["membrane"] = (e.sum(), _per_body(e, owner, bodies), size.sum(),
                       _per_body(size, owner, bodies))  # fmt: skip
    return out


@pytest.mark.parametrize("name", list(MODELS))
def test_core_energies_match_the_reference(name, simd):
    """softbody._core.eval_energies at a deformed state: each term's total and each body's
    share (springs by Model.spring_body, attachments by their particle's body, free
    particles in the totals only) equal the reference's to ULPS eps times the summed
    magnitudes; the gas at the volumes of eval_volumes (each body's own method), whose
    reference energies it equals; the grab spring's 1/2 k |T - x|^2 too."""
    model, _, data, t, q, _ = _inputs(name)
    energies = _core.eval_energies(core_model(model), data, t, q)
    volume = _core.eval_volumes(core_model(model), data, t, q)[0]
    np.testing.assert_array_equal(energies["volume"], volume)
    expected = _reference_energies(model, data, t, q, volume)
    # every registered term with an energy is checked here against its reference
    with_energy = {t["name"] for t in sb.core.terms() if t["energy"]}
    assert with_energy == set(expected) | {"grab"}
    assert set(energies) == with_energy | {"volume"}
    for term, (total, bodies, total_size, body_size) in expected.items():
        got_total, got_bodies = energies[term]
        _close(got_total, total, total_size, f"{term} total")
        _close(got_bodies, bodies, body_size, f"{term} per body")
        # every model has every term it was built with; the cloth, open, holds no gas
        # and has no attachment; material bending only where a body has it, membranes
        # only in the membranes' model
        if term == "bending":
            assert (abs(total) > 0.0) == (model.bending_hinges.shape[0] > 0), term
            continue
        present = {"cloth": ("gravity", "springs")}.get(name, tuple(expected))
        if name != "membranes":
            present = tuple(k for k in present if k != "membrane")
        assert (abs(total) > 0.0) == (term in present), term
    g = int(data.grab_particle)
    grab_size = data.grab_stiffness * (np.linalg.norm(data.grab_target) + np.linalg.norm(q[g])) ** 2
    grab_total, grab_bodies = energies["grab"]
    _close(grab_total, external.grab_energy(data, q), grab_size, "grab")
    assert (grab_total > 0.0) == (g >= 0)
    # its share goes to the grabbed particle's body
    body = int(model.particle_body[g]) if g >= 0 else -1
    np.testing.assert_array_equal(
        grab_bodies, np.where(np.arange(model.body_count) == body, grab_total, 0.0)
    )


@pytest.mark.parametrize("name", list(MODELS))
def test_diagnostics_energies_compose_the_terms(name):
    """softbody.energies (kinetic 1/2 m v^2; gravitational; spring = springs,
    attachments, bending and membranes; gas) and its per-body splits equal the reference's
    composition, the one diagnostics made before the energies moved into the core, to round-off."""
    model, control, data, t, q, qd = _inputs(name)
    state = model.state()
    state.particle_q[:], state.particle_qd[:], state.time = q, qd, t
    e = sb.energies(model, state, control)
    volume = _core.eval_volumes(core_model(model), data, t, q)[0]
    expected = _reference_energies(model, data, t, q, volume)
    kin = 0.5 * model.particle_mass * np.sum(qd**2, axis=1)
    _close(e.kinetic, kin.sum(), kin.sum(), "kinetic")
    _close(e.body_kinetic, _per_body(kin, model.particle_body, model.body_count),
           _per_body(kin, model.particle_body, model.body_count), "kinetic per body")  # fmt: skip
    sums = [
        ("gravitational", "body_gravitational", ("gravity",)),
        ("spring", "body_spring", ("springs", "attachments", "bending", "membrane")),
        ("gas", "body_gas", ("gas",)),
    ]
    for total_name, body_name, terms in sums:
        _close(getattr(e, total_name), sum(expected[k][0] for k in terms),
               sum(expected[k][2] for k in terms), total_name)  # fmt: skip
        _close(getattr(e, body_name), sum(expected[k][1] for k in terms),
               sum(expected[k][3] for k in terms), body_name)  # fmt: skip
    assert e.total == pytest.approx(e.kinetic + e.gravitational + e.spring + e.gas, rel=1e-15)
    # every registered term's energy is reported, the grab's too (outside the total)
    assert set(e.terms) == {t["name"] for t in sb.core.terms() if t["energy"]}
    assert e.terms["grab"] == pytest.approx(float(external.grab_energy(data, q)), rel=1e-12, abs=0)


# -- forces are minus the gradients of the energies --------------------------------------
def _central(function, q, direction, h):
    return (function(q + h * direction) - function(q - h * direction)) / (2.0 * h)


def _check_derivative(function, q, direction, expected, h, value_scale, size, what):
    """Central differences of ``function`` along ``direction`` equal ``expected`` within
    the estimated O(h^2) error plus the quotient's round-off (module docstring); ``size``:
    the magnitude of what ``expected`` sums, against which the check must be sharp."""
    coarse = _central(function, q, direction, h)
    fine = _central(function, q, direction, h / 2)
    allowed = 2.0 * abs(coarse - fine) / 3.0 + 64.0 * EPS * value_scale / h
    assert abs(fine - expected) <= allowed, (
        f"{what}: |FD - f . p| {abs(fine - expected):.3g} > {allowed:.3g}"
    )
    assert allowed < 1e-4 * size  # a test that can fail: sharper than what it checks


@pytest.mark.parametrize("name", ["every-term", "gas-laws", "membranes"])
def test_each_force_is_minus_the_gradient_of_the_core_energy(name):
    """For gravity, springs, attachments, the grab spring, bending and the membranes (where
    there are any) and each closed body's gas of
    the exact volume (its own share, body by body): -dE/dx . p from central differences
    of the core's energy along random p equals f(q, v = 0) . p of the term's force (the
    reference's, which test_reference.py holds equal to the core's). And the sum: the
    core's whole force at v = 0 without Control.particle_f, along p that leaves the bodies
    of other volume methods still, is -d/dx of the core's summed energies."""
    model, _, data, t, q, _ = _inputs(name)
    cm = core_model(model)
    zero = np.zeros_like(q)

    def energy(term, body=None):
        def function(x):
            out = _core.eval_energies(cm, data, t, np.ascontiguousarray(x))[term]
            return out[0] if body is None else out[1][body]

        return function

    _, pressure, grad = ref.forces.gas_state(model, data, t, q)
    pressure_force = gas.force(model, pressure, grad)
    cases = [
        ("gravity", energy("gravity"), gravity.force(model)),
        ("springs", energy("springs"), springs.force(model, q, zero)),
        ("attachments", energy("attachments"), attachments.force(model, data, q, zero)),
        ("grab", energy("grab"), external.grab_force(data, q, zero)),
    ]
    if model.bending_hinges.shape[0]:
        cases.append(("bending", energy("bending"), bending.force(model, q)))
    if model.membrane_count:
        cases.append(("membrane", energy("membrane"), membrane.force(model, q, zero)))
    exact = (model.body_volume_method == rvolume.EXACT) & (model.body_closed == 1)
    for b in np.flatnonzero(exact):
        f = np.where((model.particle_body == b)[:, None], pressure_force, 0.0)
        cases.append((f"gas of body {b}", energy("gas", b), f))
    assert len(cases) >= 5
    rng = np.random.default_rng(21)
    for what, function, f in cases:
        assert np.any(f), what
        direction = rng.normal(size=q.shape)
        size = np.sum(np.abs(f * direction))
        _check_derivative(function, q, direction, -np.sum(f * direction), 1e-4,
                          abs(function(q)) + 1.0, size, what)  # fmt: skip

    # the core's own force against the core's total energy
    still = np.zeros_like(data.particle_f)
    force = _core.eval_forces(cm, data._replace(particle_f=still), t, q, zero)[0]
    moving = (model.particle_body < 0) | exact[np.maximum(model.particle_body, 0)]
    direction = np.where(moving[:, None], rng.normal(size=q.shape), 0.0)

    def total(x):
        out = _core.eval_energies(cm, data, t, np.ascontiguousarray(x))
        return sum(out[k][0] for k in ("gravity", "springs", "attachments", "gas", "grab",
                                       "bending", "membrane"))  # fmt: skip

    size = np.sum(np.abs(force * direction))
    _check_derivative(total, q, direction, -np.sum(force * direction), 1e-4,
                      abs(total(q)) + 1.0, size, "all terms")  # fmt: skip


# -- stiffness bounds --------------------------------------------------------------------
def _stretch(length, rest_length):
    """|1 - L0 / L|, 1 where L = 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(length > 0, np.abs(1.0 - rest_length / length), 1.0)


def _numpy_bounds(model, q):
    """The Gershgorin pieces as stiffest_mode computed them in NumPy (softbody.stability's
    docstring): per part (axial k, transverse k |1 - L0/L|, whole k max(1, |1 - L0/L|),
    damping c) the row sums R_i of sqrt(w) over the springs and attachments at i, then
    max sqrt(w) (R_i / m_i + R_j / m_j) over springs and sqrt(w) R_i / m_i over
    attachments; the gas at its largest scheduled value and exact volume, its pressure
    rows |P - P_a| / 6 (|x_l - x_i| / sqrt(m_i m_j) + |x_j - x_i| / sqrt(m_i m_l)) per
    face corner and its rank-one |P'(V)| sum |g_i|^2 / m_i."""
    inv = model.particle_inv_mass
    n = model.particle_count
    i, j = model.spring_indices.T
    a = model.attachment_particle
    k, ka = model.spring_stiffness, model.attachment_stiffness
    st = _stretch(np.linalg.norm(q[j] - q[i], axis=1), model.spring_rest_length)
    sta = _stretch(np.linalg.norm(model.attachment_anchor - q[a], axis=1),
                   model.attachment_rest_length)  # fmt: skip
    weights = [
        (k, ka),
        (k * st, ka * sta),
        (k * np.maximum(1.0, st), ka * np.maximum(1.0, sta)),
        (model.spring_damping, model.attachment_damping),
    ]
    out = {"springs": [], "attachments": []}
    for ws, wa in weights:
        root = np.zeros(n)
        np.add.at(root, i, np.sqrt(ws))
        np.add.at(root, j, np.sqrt(ws))
        np.add.at(root, a, np.sqrt(wa))
        out["springs"].append(np.max(np.sqrt(ws) * (root[i] * inv[i] + root[j] * inv[j]),
                                     initial=0.0))  # fmt: skip
        out["attachments"].append(np.max(np.sqrt(wa) * root[a] * inv[a], initial=0.0))
    ratios = np.concatenate([model.spring_damping[k > 0] / k[k > 0],
                             model.attachment_damping[ka > 0] / ka[ka > 0]])  # fmt: skip
    out["damping_ratio"] = (ratios.min(), ratios.max()) if len(ratios) else (np.inf, -np.inf)
    out["pure_dampers"] = bool(np.any(model.spring_damping[k == 0] > 0)
                               or np.any(model.attachment_damping[ka == 0] > 0))  # fmt: skip

    rows = np.zeros(n)
    rank_one = 0.0
    pnet, dpdv = np.zeros(model.body_count), np.zeros(model.body_count)
    gradient = np.zeros((n, 3))
    volume = np.zeros(model.body_count)
    for b in range(model.body_count):
        t0, t1 = model.body_tri_range[b]
        tri = model.tri_indices[t0:t1]
        x = q[tri]
        normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        volume[b] = np.einsum("ij,ij->", x[:, 0] - x[:, 0].mean(axis=0), normal) / 6.0
        s0, s1 = model.body_schedule_range[b]
        value = max(model.body_gas_value[b], *model.schedule_value[s0:s1], 0.0)
        law, v = model.body_gas_law[b], volume[b]
        if law == gas.FIXED_PRESSURE:
            pressure, slope = value, 0.0
        elif law == gas.ISOTHERMAL:
            pressure, slope = value / v, -value / v**2
        else:
            g = model.body_gas_gamma[b]
            pressure = value * model.body_gas_reference_volume[b] ** (g - 1.0) / v**g
            slope = -g * pressure / v
        pnet[b], dpdv[b] = pressure - model.body_ambient_pressure[b], slope
        for c in range(3):
            ci, cj, cl = tri[:, c], tri[:, (c + 1) % 3], tri[:, (c + 2) % 3]
            lij = np.linalg.norm(x[:, (c + 1) % 3] - x[:, c], axis=1)
            lil = np.linalg.norm(x[:, (c + 2) % 3] - x[:, c], axis=1)
            row = abs(pnet[b]) / 6.0 * (lil * np.sqrt(inv[ci] * inv[cj])
                                        + lij * np.sqrt(inv[ci] * inv[cl]))  # fmt: skip
            np.add.at(rows, ci, row)
        grad = np.zeros((n, 3))
        for c in range(3):
            np.add.at(grad, tri[:, c], normal / 6.0)
        rank_one = max(rank_one, abs(slope) * float(np.sum(inv * np.sum(grad**2, axis=1))))
        gradient += grad
    out.update(pressure_rows=rows.max(initial=0.0), gas_rank_one=rank_one, body_pnet=pnet,
               body_dpdv=dpdv, volume_gradient=gradient, volume=volume)  # fmt: skip
    # bending: per hinge w |g_a| / sqrt(m_a) sum_b |g_b| / sqrt(m_b) on each corner's row,
    # w = 2 k (1 + 2 |theta - theta0|)
    theta, g, _ = bending.angles_and_gradients(model, q)
    hinge = model.bending_hinges
    w = 2.0 * model.bending_stiffness * (1.0 + 2.0 * np.abs(bending.excess(model, theta)))
    scaled = np.linalg.norm(g, axis=2) * np.sqrt(inv[hinge])  # (H, 4)
    rows = np.zeros(n)
    np.add.at(rows, hinge.reshape(-1),
              (w[:, None] * scaled * scaled.sum(axis=1, keepdims=True)).reshape(-1))  # fmt: skip
    out["bending"] = rows.max(initial=0.0)
    return out


def _relative_volume_error(model, q, volume):
    """Round-off of each body's exact volume relative to it, (B,): sqrt(T) eps times the
    sum of the face terms' magnitudes |a - r| |e1| |e2| / 6 (the larger of the two
    reference points r, the body's first particle and the mean of the first corners)."""
    out = np.zeros(model.body_count)
    for b, ((p0, _), (t0, t1)) in enumerate(
        zip(model.body_particle_range, model.body_tri_range, strict=True)
    ):
        tri = model.tri_indices[t0:t1]
        x = q[tri]
        e = np.linalg.norm(x[:, 1] - x[:, 0], axis=1) * np.linalg.norm(x[:, 2] - x[:, 0], axis=1)
        far = np.maximum(np.linalg.norm(x[:, 0] - q[p0], axis=1),
                         np.linalg.norm(x[:, 0] - x[:, 0].mean(axis=0), axis=1))  # fmt: skip
        out[b] = np.sqrt(len(tri)) * EPS * np.sum(far * e) / 6.0 / abs(volume[b])
    return out


@pytest.mark.parametrize("name", BOUND_MODELS)
def test_bound_pieces_match_the_numpy_formulas(name, simd):
    """softbody._core.stiffness_bounds at a deformed state, piece by piece, against the
    NumPy formulas (``_numpy_bounds``): the springs' and attachments' row bounds of each
    part, c / k range and pure dampers, the pressure rows, the rank-one term, P - P_a,
    P'(V) and dV/dx, the bending rows (the "terms" entry: each term's own bound form).
    Tolerances from round-off: sums of positive terms to ULPS eps
    relative; sqrt(k |1 - L0/L|) carries |1 - L0/L|'s absolute round-off eps divided by
    2 sqrt(|1 - L0/L|); the gas's pieces carry its volume's relative round-off (times
    gamma, or 2 for P' = -nRT / V^2), enlarged by P / |P - P_a| where P - P_a cancels."""
    model, _, _, _, q, _ = _inputs(name)
    got = _core.stiffness_bounds(core_model(model), control_data(model), q)
    want = _numpy_bounds(model, q)
    i, j = model.spring_indices.T
    st = _stretch(np.linalg.norm(q[j] - q[i], axis=1), model.spring_rest_length)
    transverse = 1.0 + 1.0 / np.sqrt(st[st > 0].min() if np.any(st > 0) else 1.0)
    # the springs and attachments share their rows (bounded by the larger of theirs), the
    # gas holds the volume mode (reported apart)
    assert list(got["shared_rows"]) == ["springs", "attachments"]
    assert list(got["volume_modes"]) == ["gas"]
    for term in ("springs", "attachments"):
        for part, (g, w) in enumerate(zip(got["terms"][term], want[term], strict=True)):
            scale = w * (transverse if part == 1 else 1.0)
            _close(g, w, scale, f"{term} part {part}")
    np.testing.assert_array_equal(got["damping_ratio"], want["damping_ratio"])
    assert got["pure_dampers"] == want["pure_dampers"]

    relative_volume = _relative_volume_error(model, q, want["volume"])
    gamma = np.where(model.body_gas_law == gas.ADIABATIC, model.body_gas_gamma, 2.0)
    pressure = want["body_pnet"] + model.body_ambient_pressure
    fixed = model.body_gas_law == gas.FIXED_PRESSURE
    net_error = np.where(fixed, 0.0, gamma * relative_volume / ULPS / EPS) * np.abs(pressure)
    _close(got["body_pnet"], want["body_pnet"], np.abs(pressure) + net_error, "P - P_a")
    slope_relative = np.where(fixed, 1.0, 1.0 + (gamma + 1.0) * relative_volume / ULPS / EPS)
    _close(got["body_dpdv"], want["body_dpdv"], np.abs(want["body_dpdv"]) * slope_relative,
           "dP/dV")  # fmt: skip
    tri = model.tri_indices
    size = (
        np.linalg.norm(q[tri[:, 1]] - q[tri[:, 0]], axis=1)
        * np.linalg.norm(q[tri[:, 2]] - q[tri[:, 0]], axis=1)
        / 6.0
    )
    face_scale = np.zeros(model.particle_count)
    for c in range(3):
        np.add.at(face_scale, tri[:, c], size)
    _close(got["volume_gradient"], want["volume_gradient"], face_scale[:, None], "dV/dx")
    net = np.abs(want["body_pnet"])
    pressure_relative = np.max((np.abs(pressure) + net_error)[net > 0] / net[net > 0],
                               initial=1.0)  # fmt: skip
    # the gas's own bound: its pressure rows plus its volume mode (undamped and whole)
    gas_parts, rank_one = got["terms"]["gas"], got["volume_modes"]["gas"]
    assert gas_parts[0] == gas_parts[3] == 0.0 and gas_parts[1] == gas_parts[2]
    rank_one_scale = want["gas_rank_one"] * np.max(slope_relative, initial=1.0)
    _close(rank_one, want["gas_rank_one"], rank_one_scale, "rank one")
    _close(gas_parts[1], want["pressure_rows"] + want["gas_rank_one"],
           want["pressure_rows"] * pressure_relative + rank_one_scale, "pressure rows")  # fmt: skip
    # the gradients' round-off relative to |g| grows as a hinge's triangles thin; these
    # meshes' are near equilateral, so a few ULPS each, summed over a row's few hinges
    # (its own bound: parts undamped and whole; registered as a bound form, it is present
    # in every model and 0 without hinges)
    own = got["terms"]["bending"]
    assert own[0] == own[3] == 0.0 and own[1] == own[2]
    assert own[1] == pytest.approx(want["bending"], rel=1e-12, abs=0.0)
    assert (own[1] > 0.0) == (model.bending_hinges.shape[0] > 0)
    # every piece is there to be checked (the cloth has no attachment, and its gas no
    # rank-one term: an open surface's pressure does not change with its volume)
    for piece in (*got["terms"]["springs"], want["pressure_rows"]):
        assert piece > 0.0
    assert (got["terms"]["attachments"][0] > 0.0) == (name != "cloth")
    assert (rank_one > 0.0) == (name != "cloth")


@pytest.mark.parametrize("name", BOUND_MODELS)
def test_stiffest_mode_composes_the_term_bounds(name):
    """stiffest_mode without the spectral bounds is the Gershgorin composition of the
    NumPy pieces (softbody.stability's docstring): omega_damped^2 the larger of the
    springs' and attachments' axial rows, the undamped part their transverse rows plus
    the pressure's (rows and rank-one, added by Weyl) and the bending rows, omega^2 the
    smaller of damped + undamped and whole + pressure + bending, beta the c / k range
    (inf with a pure damper), all to round-off, at the model's rest and at a deformed
    state."""
    model, _, _, _, q, _ = _inputs(name)
    for x in (model.particle_q, q):
        mode = stiffest_mode(model, x, spectral=False)
        want = _numpy_bounds(model, x)
        damped, transverse, whole, rate = (max(s, a) for s, a in zip(
            want["springs"], want["attachments"], strict=True))  # fmt: skip
        pressure = want["pressure_rows"] + want["gas_rank_one"]
        undamped = transverse + pressure + want["bending"]
        total = min(damped + undamped, whole + pressure + want["bending"])
        rel = 1e-12  # the pieces' round-off (test above) is far below this
        assert mode.omega_damped == pytest.approx(np.sqrt(damped), rel=rel)
        assert mode.omega_undamped == pytest.approx(np.sqrt(undamped), rel=rel)
        assert mode.omega == pytest.approx(np.sqrt(total), rel=rel)
        assert mode.damping_rate == pytest.approx(rate, rel=rel)
        assert mode.omega_pressure == pytest.approx(np.sqrt(pressure), rel=rel)
        assert mode.omega_gas == pytest.approx(np.sqrt(want["gas_rank_one"]), rel=rel)
        low, high = want["damping_ratio"]
        beta = (low, np.inf if want["pure_dampers"] else high)
        assert mode.damping_per_stiffness == pytest.approx(beta, rel=1e-15)
        assert mode.zeta == pytest.approx(low * damped / (2.0 * mode.omega), rel=rel)
