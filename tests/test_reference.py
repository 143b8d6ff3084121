"""The compiled core against the readable NumPy reference (softbody.reference), and the
reference against calculus.

Core vs reference: forces, volumes, pressures, dV/dx and the Jacobian product agree to
round-off on every instruction set this CPU runs. The tolerance is derived, not tuned:
each quantity is a sum of products, and the two codes may round each product and add
them in another order (vertex-major lanes, AVX-512's refined reciprocal square root), so
their difference is at most a few units of round-off eps = 2^-52 times the sum of the
magnitudes of what was added (``ULPS`` eps sum |terms|). The magnitudes come from the
reference's own inputs (``_force_scale``, ``_volume_scale``...).

Reference vs calculus: each conservative force is minus the gradient of its energy and
the Jacobian product is the derivative of the force, checked by central differences along
random directions. Central differences err by O(h^2): the error at h/2 is a quarter of
that at h, so |D(h/2) - exact| <= |D(h) - D(h/2)| / 3 up to higher orders; the checks
allow twice that plus the round-off of the difference quotient (eps |E| / h).

Every test that calls the core runs on each instruction set ``softbody.core.simd_paths()``
lists (the ``simd`` fixture); the calculus checks read the reference alone. Reference
steps of backward Euler and projective dynamics close the file.
"""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from softbody import _core, core
from softbody import reference as ref
from softbody.core import core_model
from softbody.reference import attachments, drag, external, gas, gravity, jacobians, springs
from softbody.reference import volume as rvolume

EPS = np.finfo(float).eps
#: Units of round-off allowed per unit of summed magnitude: a handful of roundings in
#: each product plus the additions of a particle's terms (module docstring).
ULPS = 16.0


# -- models ------------------------------------------------------------------------------
def _ball(law: str) -> tuple[sb.Model, sb.Control]:
    """An icosphere ball (162 particles) with a gas of one law (with a schedule and an
    ambient pressure), two pinned particles, bending springs, damping and an attachment;
    the control overrides nothing but adds external forces and a grab."""
    gases = {
        "isothermal": sb.Gas.isothermal(
            40.0, ambient_pressure=20.0, schedule=[(0.0, 30.0), (0.05, 50.0), (0.1, 45.0)]
        ),
        "fixed": sb.Gas.fixed_pressure(300.0, ambient_pressure=120.0),
        "adiabatic": sb.Gas.adiabatic(35.0, gamma=1.4, reference_volume=0.1, ambient_pressure=8.0),
    }
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(
        sb.icosphere(2, radius=0.3, center=(0.1, 0.5, -0.2)), mass=1.0, stiffness=400.0,
        damping=0.5, gas=gases[law], bend_stiffness=20.0, bend_damping=0.1, pinned=[0, 7],
    )  # fmt: skip
    b.add_attachment(5, anchor=(0.1, 1.2, -0.2), stiffness=50.0, damping=1.0, rest_length=0.2)
    model = b.finalize()
    control = model.control()
    control.particle_f[:] = np.random.default_rng(11).normal(0.0, 0.5, control.particle_f.shape)
    control.grab_particle = 40
    control.grab_target = np.array([0.5, 0.9, 0.0])
    control.grab_stiffness, control.grab_damping = 30.0, 0.4
    return model, control


def _two_bodies() -> tuple[sb.Model, sb.Control]:
    """Two exact bodies (isothermal, adiabatic), a user spring between them, a free
    particle on a user spring and an attachment, a gas override and moved anchors."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(1, radius=0.3), mass=0.8, stiffness=300.0, damping=0.3,
                    gas=sb.Gas.isothermal(30.0), mass_distribution="area")  # fmt: skip
    b.add_soft_body(sb.icosphere(2, radius=0.25, center=(0.8, 0.1, 0.0)), mass=0.5,
                    stiffness=250.0, damping=0.2, gas=sb.Gas.adiabatic(25.0, gamma=1.3),
                    bend_stiffness=10.0)  # fmt: skip
    free = b.add_particle((0.3, 0.9, 0.1), mass=0.05, velocity=(0.1, 0.0, 0.0))
    b.add_spring(0, 50, stiffness=30.0, damping=0.2, rest_length=0.5)  # between the bodies
    b.add_spring(free, 3, stiffness=20.0, damping=0.1, rest_length=0.4)
    b.add_attachment(free, anchor=(0.3, 1.5, 0.1), stiffness=40.0, damping=0.5)
    b.add_attachment(60, anchor=(0.8, 0.6, 0.0), stiffness=25.0, rest_length=0.1)
    model = b.finalize()
    control = model.control()
    control.body_gas_nrt = np.array([36.0, np.nan])
    control.attachment_anchor = model.attachment_anchor + np.array([0.05, -0.02, 0.03])
    return model, control


def _bounding() -> tuple[sb.Model, sb.Control]:
    """One body for each bounding method and one of Monte Carlo volume, each gas law."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.3), mass=1.0, stiffness=400.0, damping=0.5,
                    volume_method="bounding_box", gas=20.0)  # fmt: skip
    b.add_soft_body(sb.icosphere(1, radius=0.25, center=(0.8, 0.0, 0.0)), mass=0.5,
                    stiffness=300.0, damping=0.3, volume_method="bounding_sphere",
                    gas=sb.Gas.fixed_pressure(80.0, ambient_pressure=10.0))  # fmt: skip
    b.add_soft_body(sb.icosphere(2, radius=0.3, center=(0.0, 0.9, 0.0)), mass=1.0,
                    stiffness=400.0, damping=0.5, volume_method="bounding_ellipsoid",
                    gas=sb.Gas.adiabatic(30.0, schedule=[(0.0, 30.0), (0.05, 60.0)]))  # fmt: skip
    b.add_soft_body(sb.box((0.5, 0.4, 0.3), center=(0.9, 0.9, 0.0), subdivisions=2), mass=0.5,
                    stiffness=300.0, damping=0.3, volume_method="monte_carlo",
                    monte_carlo_samples=2048, seed=3, gas=15.0)  # fmt: skip
    return b.finalize(), None


def _cloth() -> tuple[sb.Model, sb.Control]:
    """An open surface (a cloth) with a fixed-pressure gust, two pinned corners, bending
    springs and face drag in a wind the control overrides; a corner grabbed."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_cloth(sb.rectangle((1.0, 0.8), (10, 8)), mass=0.3, stiffness=200.0, damping=0.2,
                pressure=sb.Gas.fixed_pressure(2.0, schedule=[(0.0, 0.0), (0.1, 4.0)]),
                pinned=[0, 10], bend_stiffness=5.0, bend_damping=0.01,
                drag_coefficient=1.2)  # fmt: skip
    b.set_air(density=1.2, wind=(0.0, 0.0, 3.0))
    model = b.finalize()
    control = model.control()
    control.wind = np.array([1.0, -0.5, 4.0])
    control.grab_particle = model.particle_count - 1
    control.grab_target = model.particle_q[-1] + np.array([0.1, 0.0, 0.2])
    control.grab_stiffness, control.grab_damping = 10.0, 0.1
    return model, control


def _drag_ball() -> tuple[sb.Model, sb.Control]:
    """A ball with face drag in the model's wind, and a second one without drag."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.3), mass=0.2, stiffness=300.0, damping=0.2,
                    gas=sb.Gas.isothermal(20.0, ambient_pressure=30.0),
                    drag_coefficient=0.5)  # fmt: skip
    b.add_soft_body(sb.icosphere(1, radius=0.2, center=(0.7, 0.0, 0.0)), mass=0.2,
                    stiffness=300.0, damping=0.2, gas=10.0)  # fmt: skip
    b.set_air(density=1.2, wind=(2.0, 0.5, -1.0))
    return b.finalize(), None


MODELS = {
    "ball-isothermal": lambda: _ball("isothermal"),
    "ball-fixed": lambda: _ball("fixed"),
    "ball-adiabatic": lambda: _ball("adiabatic"),
    "two-bodies": _two_bodies,
    "bounding-and-monte-carlo": _bounding,
    "cloth": _cloth,
    "drag-ball": _drag_ball,
}
#: Models whose every body is closed with the exact volume or open with a fixed pressure:
#: there the pressure force has the exact derivative the Jacobian product applies.
EXACT_MODELS = ["ball-isothermal", "ball-fixed", "ball-adiabatic", "two-bodies", "cloth"]
_BUILT: dict = {}


def _model(name: str):
    if name not in _BUILT:
        _BUILT[name] = MODELS[name]()
    return _BUILT[name]


def _state(model: sb.Model, seed: int, *, stretch: float = 1.0, amplitude: float = 0.01):
    """Positions (each body scaled by ``stretch`` about its centre, then each particle
    moved by up to ``amplitude`` [m]) and velocities (0.3 m/s spread) drawn with
    ``seed``, (N, 3) each."""
    rng = np.random.default_rng(seed)
    q = model.particle_q.copy()
    for p0, p1 in model.body_particle_range:
        c = q[p0:p1].mean(axis=0)
        q[p0:p1] = c + stretch * (q[p0:p1] - c)
    q += rng.uniform(-amplitude, amplitude, q.shape)
    return q, rng.normal(0.0, 0.3, q.shape)


def _inputs(name: str, t: float = 0.03, seed: int = 3, **state):
    model, control = _model(name)
    data = ref.control_arrays(model, control)
    q, qd = _state(model, seed, **state)
    return model, data, t, q, qd


@pytest.fixture(params=core.simd_paths())
def simd(request):
    """Each instruction set this CPU runs, restored afterwards."""
    before = core.simd_path()
    core.use_simd(request.param)
    yield request.param
    core.use_simd(before)


# -- round-off scales --------------------------------------------------------------------
def _scatter(n: int, index: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.zeros(n)
    np.add.at(out, index, values)
    return out


def _volume_scale(model: sb.Model, q: np.ndarray) -> np.ndarray:
    """:func:`_volume_scales` of the model's bodies by their own methods, (B,) [m^3]."""
    return _volume_scales(q, model.tri_indices, model.body_particle_range, model.body_tri_range,
                          model.body_volume_method, model.body_mc_range,
                          model.mc_samples)  # fmt: skip


def _volume_scales(q, tri_indices, particle_range, tri_range, methods, mc_range, samples):
    """Round-off scale of each body's volume [m^3], (B,) (the arguments of body_volumes):
    a long sum's n roundings walk randomly, so sqrt(n) times the sum of its terms'
    magnitudes. Exact: n = T faces of sum_t |a_t - r| |e1| |e2| / 6; Monte Carlo: the same
    sum as the volume with |y - y0|, about n = 2 S crossings (S lines, each crossing these
    convex bodies twice); a bounding object's few products: its own volume."""
    out = np.zeros(len(particle_range))
    for b, ((p0, p1), (t0, t1)) in enumerate(zip(particle_range, tri_range, strict=True)):
        tri = tri_indices[t0:t1]
        method = int(methods[b])
        if method == rvolume.EXACT:
            a = q[tri[:, 0]]
            e1 = np.linalg.norm(q[tri[:, 1]] - a, axis=1)
            e2 = np.linalg.norm(q[tri[:, 2]] - a, axis=1)
            terms = np.linalg.norm(a - q[p0], axis=1) * e1 * e2 / 6.0
            out[b] = np.sqrt(len(tri)) * terms.sum()
        elif method == rvolume.MONTE_CARLO:
            lo, hi = rvolume.bounds(q[p0:p1])
            s0, s1 = mc_range[b]
            size = rvolume.monte_carlo(q, tri, lo, hi, samples[s0:s1], absolute=True)
            out[b] = np.sqrt(2.0 * (s1 - s0)) * size
        else:
            out[b] = abs(rvolume.bounding(q[p0:p1], method))
    return out


def _gradient_scale(model: sb.Model, q: np.ndarray) -> np.ndarray:
    """Per particle, the sum over its faces of |e1| |e2| / 6 [m^2], (N,): the size of
    the cross products dV/dx adds."""
    tri = model.tri_indices
    a = q[tri[:, 0]]
    size = np.linalg.norm(q[tri[:, 1]] - a, axis=1) * np.linalg.norm(q[tri[:, 2]] - a, axis=1)
    return sum(_scatter(len(q), tri[:, k], size / 6.0) for k in range(3))


def _pressure_scale(model, data, t, q) -> np.ndarray:
    """Round-off scale of each body's absolute pressure [Pa], (B,): P times the relative
    scale of its volume, times gamma (P ~ V^-gamma); a fixed pressure is exact."""
    v = rvolume.volumes(model, q)
    p = gas.pressures(model, data, t, v)
    gamma = np.where(model.body_gas_law == gas.ADIABATIC, model.body_gas_gamma, 1.0)
    relative = 1.0 + gamma * _volume_scale(model, q) / np.abs(v)
    return np.where(model.body_gas_law == gas.FIXED_PRESSURE, np.abs(p), np.abs(p) * relative)


def _force_scale(model, data, t, q, qd) -> np.ndarray:
    """Sum of the magnitudes of everything added into each particle's force [N], (N,):
    m |g|; per spring and attachment k (L + L0) + c |relative velocity|; per body
    (P + P_a) times the gradient's scale, plus |dP| |dV/dx|; |external|; the grab's
    k (|T| + |x|) + c |v|; drag, |F_t| / 3 per face."""
    n = model.particle_count
    scale = model.particle_mass * np.linalg.norm(model.gravity)
    i, j = model.spring_indices.T
    length = springs.lengths(model, q)
    dv = np.linalg.norm(qd[j] - qd[i], axis=1)
    per_spring = model.spring_stiffness * (length + model.spring_rest_length)
    per_spring = per_spring + model.spring_damping * dv
    scale += _scatter(n, i, per_spring) + _scatter(n, j, per_spring)
    a = model.attachment_particle
    la = np.linalg.norm(np.asarray(data.attachment_anchor) - q[a], axis=1)
    per_att = model.attachment_stiffness * (la + model.attachment_rest_length)
    scale += _scatter(n, a, per_att + model.attachment_damping * np.linalg.norm(qd[a], axis=1))
    v = rvolume.volumes(model, q)
    pressure = gas.pressures(model, data, t, v)
    gradient = rvolume.gradient(model, q)
    body = np.maximum(model.particle_body, 0)
    inside = model.particle_body >= 0
    p_size = (np.abs(pressure) + model.body_ambient_pressure)[body]
    p_error = _pressure_scale(model, data, t, q)[body]
    scale += np.where(
        inside,
        p_size * _gradient_scale(model, q) + p_error * np.linalg.norm(gradient, axis=1),
        0.0,
    )
    scale += np.linalg.norm(np.asarray(data.particle_f), axis=1)
    g = int(data.grab_particle)
    if g >= 0:
        scale[g] += data.grab_stiffness * (
            np.linalg.norm(data.grab_target) + np.linalg.norm(q[g])
        ) + data.grab_damping * np.linalg.norm(qd[g])
    face = np.linalg.norm(drag.face_forces(model, data, q, qd), axis=1) / 3.0
    scale += sum(_scatter(n, model.tri_indices[:, k], face) for k in range(3))
    return scale


def _close(actual, expected, scale, what):
    """|actual - expected| <= ULPS eps scale, element-wise (scale broadcast to rows)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = np.asarray(scale, dtype=float)
    if actual.ndim == 2 and scale.ndim == 1:
        scale = scale[:, None]
    tol = np.broadcast_to(ULPS * EPS * scale, actual.shape)
    error = np.abs(actual - expected)
    worst = np.unravel_index(np.argmax(error - tol), error.shape) if error.size else ()
    assert np.all(error <= tol), (
        f"{what}: |difference| {error[worst]:.3g} > tolerance {tol[worst]:.3g} at {worst}"
    )


# -- the core against the reference ------------------------------------------------------
@pytest.mark.parametrize("name", list(MODELS))
def test_core_forces_volumes_and_pressures_match_the_reference(name, simd):
    """softbody._core.eval_forces at a deformed, moving state: the force (N, 3), every
    body's volume by its method, its pressure and the exact dV/dx equal the reference's
    to ULPS eps times the summed magnitudes (module docstring)."""
    model, data, t, q, qd = _inputs(name)
    f, v, p, g = _core.eval_forces(core_model(model), data, t, q, qd)
    expected = ref.forces.eval_forces(model, data, t, q, qd)
    _close(v, expected.volume, _volume_scale(model, q), "volume")
    _close(p, expected.pressure, _pressure_scale(model, data, t, q), "pressure")
    _close(g, expected.volume_gradient, _gradient_scale(model, q), "dV/dx")
    _close(f, expected.force, _force_scale(model, data, t, q, qd), "force")
    # the reference is not trivially equal: every model has every term it was built with
    terms = ref.forces.terms(model, data, t, q, qd)
    for term in ("gravity", "springs", "gas"):
        assert np.abs(terms[term]).max() > 0.0, term


@pytest.mark.parametrize("name", list(MODELS))
def test_core_volume_calls_match_the_reference(name, simd):
    """softbody._core.eval_volumes (volumes, pressures, dV/dx) and body_volumes (plain
    arrays, each method forced on every body) equal the reference's volumes to round-off."""
    model, data, t, q, _ = _inputs(name, t=0.07, seed=5)
    v, p, g = _core.eval_volumes(core_model(model), data, t, q)
    ev, ep, eg = ref.forces.gas_state(model, data, t, q)
    _close(v, ev, _volume_scale(model, q), "volume")
    _close(p, ep, _pressure_scale(model, data, t, q), "pressure")
    _close(g, eg, _gradient_scale(model, q), "dV/dx")
    samples = np.random.default_rng(2).random((1024, 2))
    mc_range = np.tile([0, len(samples)], (model.body_count, 1))
    for method in range(5):
        methods = np.full(model.body_count, method, dtype=np.int64)
        args = (q, model.tri_indices, model.body_particle_range, model.body_tri_range, methods,
                mc_range, samples)  # fmt: skip
        _close(_core.body_volumes(*args), rvolume.body_volumes(*args),
               _volume_scales(*args), f"volume by method {method}")  # fmt: skip


@pytest.mark.parametrize("name", list(MODELS))
def test_core_jacobian_product_matches_the_reference(name, simd):
    """softbody._core.apply_jacobians: alpha_m M p + alpha_c C p + alpha_k K p for a
    random p, with and without attachments, equals the reference's product to ULPS eps
    times the summed magnitudes of its terms; the reference's own prepared inputs are
    passed to both, so only the product is compared."""
    model, data, t, q, _ = _inputs(name)
    inputs = jacobians.prepare(model, data, t, q)
    p = np.random.default_rng(9).normal(size=q.shape)
    alphas = (2.0, -0.3, -0.7)
    n = model.particle_count
    # the magnitudes each row sums: m |p|; per spring (a + b + c) |p_j - p_i|; per
    # attachment and grab (k + c) |p|; per body |P'| |g| sum |g . p| and |P - P_a| / 6
    # (|d1| |e2| + |e1| |d2|) per face
    i, j = model.spring_indices.T
    per = (inputs.spring_a + inputs.spring_b + model.spring_damping) * np.linalg.norm(
        p[j] - p[i], axis=1
    )
    scale = 2.0 * model.particle_mass * np.linalg.norm(p, axis=1)
    scale += _scatter(n, i, per) + _scatter(n, j, per)
    a = model.attachment_particle
    scale += _scatter(n, a, (model.attachment_stiffness + model.attachment_damping)
                      * np.linalg.norm(p[a], axis=1))  # fmt: skip
    if data.grab_particle >= 0:
        scale[data.grab_particle] += (data.grab_stiffness + data.grab_damping) * np.linalg.norm(
            p[data.grab_particle]
        )
    gnorm = np.linalg.norm(inputs.volume_gradient, axis=1)
    for b, ((p0, p1), (t0, t1)) in enumerate(
        zip(model.body_particle_range, model.body_tri_range, strict=True)
    ):
        gp = np.sum(np.abs(inputs.volume_gradient[p0:p1] * p[p0:p1]))
        scale[p0:p1] += np.abs(inputs.body_dpdv[b]) * gnorm[p0:p1] * gp
        tri = model.tri_indices[t0:t1]
        e = [np.linalg.norm(q[tri[:, k]] - q[tri[:, 0]], axis=1) for k in (1, 2)]
        d = [np.linalg.norm(p[tri[:, k]] - p[tri[:, 0]], axis=1) for k in (1, 2)]
        face = np.abs(inputs.body_pnet[b]) / 6.0 * (d[0] * e[1] + e[0] * d[1])
        scale += sum(_scatter(n, tri[:, k], face) for k in range(3))
    for with_attachments in (True, False):
        out = np.full_like(q, np.nan)
        _core.apply_jacobians(core_model(model), data, q, p, *alphas, out,
                              leave_out=[] if with_attachments else ["attachments"],
                              **inputs.core_arguments())  # fmt: skip
        expected = jacobians.apply_jacobians(
            model, data, q, p, *alphas, inputs, with_attachments=with_attachments
        )
        _close(out, expected, scale, f"product (attachments={with_attachments})")


# -- the reference against calculus ------------------------------------------------------
def _central(function, q: np.ndarray, direction: np.ndarray, h: float):
    return (function(q + h * direction) - function(q - h * direction)) / (2.0 * h)


def _check_derivative(function, q, direction, expected, h, value_scale, size, what):
    """Central differences of ``function`` along ``direction`` at q equal ``expected``
    within the O(h^2) error estimated from steps h and h/2, plus the difference
    quotient's round-off (module docstring); ``size``: the magnitude of what
    ``expected`` sums, against which the check must be sharp."""
    coarse = _central(function, q, direction, h)
    fine = _central(function, q, direction, h / 2)
    truncation = 2.0 * np.abs(coarse - fine) / 3.0
    roundoff = 64.0 * EPS * value_scale / h
    error = np.abs(fine - expected)
    assert np.all(error <= truncation + roundoff), (
        f"{what}: |FD - exact| {np.max(error):.3g} > {np.max(truncation + roundoff):.3g}"
    )
    # a test that can fail: the check is sharper than what it checks
    assert np.max(truncation + roundoff) < 1e-4 * size


@pytest.mark.parametrize("name", EXACT_MODELS)
def test_each_conservative_force_is_minus_the_gradient_of_its_energy(name):
    """For gravity, springs, attachments, the grab spring and the gas (closed bodies of
    the exact volume): -dE/dx . p from central differences of the reference energy along
    random p equals f(q, v = 0) . p of the reference force."""
    model, data, t, q, _ = _inputs(name)
    zero = np.zeros_like(q)
    closed = model.body_closed == 1

    def gas_force(x):
        v = rvolume.exact_volumes(model, x)
        f = gas.force(model, gas.pressures(model, data, t, v), rvolume.gradient(model, x))
        return np.where(closed[np.maximum(model.particle_body, 0)][:, None]
                        & (model.particle_body >= 0)[:, None], f, 0.0)  # fmt: skip

    cases = {
        "gravity": (lambda x: gravity.energy(model, x), lambda x: gravity.force(model)),
        "springs": (lambda x: springs.energy(model, x), lambda x: springs.force(model, x, zero)),
        "attachments": (
            lambda x: attachments.energy(model, data, x),
            lambda x: attachments.force(model, data, x, zero),
        ),
        "grab": (
            lambda x: external.grab_energy(data, x),
            lambda x: external.grab_force(data, x, zero),
        ),
        "gas": (lambda x: gas.potential_energy(model, data, t, x), gas_force),
    }
    rng = np.random.default_rng(21)
    checked = 0
    for term, (energy, force) in cases.items():
        f = force(q)
        if not np.any(f):
            continue  # the model has no such term
        checked += 1
        for _ in range(3):
            direction = rng.normal(size=q.shape)
            expected = -np.sum(f * direction)
            scale = abs(energy(q)) + 1.0
            size = np.sum(np.abs(f * direction))
            _check_derivative(energy, q, direction, expected, 1e-4, scale, size, term)
    assert checked >= 3


@pytest.mark.parametrize("name", EXACT_MODELS)
def test_jacobian_product_is_the_derivative_of_the_force(name):
    """With every spring stretched (bodies scaled by 1.1 and moved by up to 1 mm, so the
    dropped compressive stiffness is not met): K p = d/de f(q + e p, 0) (K is the elastic
    forces' stiffness: the dampers' turning with u is left out, so it is taken at rest)
    and C p = d/de f(q, v + e p) of the terms the product covers (springs, attachments,
    grab, gas), by central differences."""
    model, data, t, q, qd = _inputs(name, stretch=1.1, amplitude=1e-3)
    assert np.all(springs.lengths(model, q) > model.spring_rest_length)
    inputs = jacobians.prepare(model, data, t, q)
    rng = np.random.default_rng(5)

    def covered(x, v):
        _, pressure, grad = ref.forces.gas_state(model, data, t, x)
        return (
            springs.force(model, x, v)
            + attachments.force(model, data, x, v)
            + external.grab_force(data, x, v)
            + gas.force(model, pressure, grad)
        )

    scale = np.abs(covered(q, qd)).max() + 1.0
    for _ in range(2):
        p = rng.normal(size=q.shape)
        kp = jacobians.apply_jacobians(model, data, q, p, 0.0, 0.0, 1.0, inputs)
        cp = jacobians.apply_jacobians(model, data, q, p, 0.0, 1.0, 0.0, inputs)
        _check_derivative(lambda x: covered(x, 0.0 * qd), q, p, kp, 1e-5, scale, np.abs(kp).max(),
                          "K p")  # fmt: skip
        _check_derivative(lambda v: covered(q, v), qd, p, cp, 1e-3, scale, np.abs(cp).max(),
                          "C p")  # fmt: skip
        mp = jacobians.apply_jacobians(model, data, q, p, 1.0, 0.0, 0.0, inputs)
        np.testing.assert_array_equal(mp, model.particle_mass[:, None] * p)


@pytest.mark.parametrize("name", ["ball-isothermal", "ball-adiabatic", "two-bodies"])
def test_pressure_force_has_no_net_force_or_torque_on_a_closed_body(name, simd):
    """The exact dV/dx of a closed surface sums to zero and has zero moment: sum_i g_i = 0
    and sum_i x_i x g_i = 0 (each face's n/6 on three corners: the sum of n_t over a closed
    surface vanishes, and so does that of (a + b + c) x n_t). So the pressure force
    (P - P_a) g, the reference's and the core's (its dV/dx from eval_forces), moves and
    turns nothing: the sums vanish to ULPS eps times the sum of the magnitudes added,
    |P - P_a| |g_i|'s round-off scale (and |x_i| times it for the torque)."""
    model, data, t, q, qd = _inputs(name)
    _, pressure, grad = ref.forces.gas_state(model, data, t, q)
    core_grad = _core.eval_forces(core_model(model), data, t, q, qd)[3]
    net = pressure - model.body_ambient_pressure
    scale = _gradient_scale(model, q)
    for b, (p0, p1) in enumerate(model.body_particle_range):
        x = q[p0:p1] - q[p0:p1].mean(axis=0)
        size = np.abs(net[b]) * scale[p0:p1]
        for g in (grad, core_grad):
            f = net[b] * g[p0:p1]
            assert np.abs(f.sum(axis=0)).max() <= ULPS * EPS * size.sum()
            torque = np.cross(x, f).sum(axis=0)
            assert np.abs(torque).max() <= ULPS * EPS * (np.linalg.norm(x, axis=1) * size).sum()
            assert np.abs(f).max() > 1.0  # the gas pushes


def test_reference_terms_match_their_closed_forms():
    """Spot values by hand: a spring stretched by 0.1 m with k = 30 N/m pulls its ends
    together with 3 N and holds 0.15 J; at t = 0 the isothermal ball's schedule gives
    nRT = 30 J and the pressure 30 J / V, and halfway between its points (0, 30) and
    (0.05, 50) it gives 40; a unit cube's box volume is 1 and its bounding sphere's
    (4/3) pi (sqrt 3 / 2)^3."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    i = b.add_particle((0.0, 0.0, 0.0), mass=1.0)
    j = b.add_particle((0.5, 0.0, 0.0), mass=1.0)
    b.add_spring(i, j, stiffness=30.0, rest_length=0.4)
    model = b.finalize()
    q = model.particle_q
    f = springs.force(model, q, np.zeros_like(q))
    np.testing.assert_allclose(f, [[3.0, 0.0, 0.0], [-3.0, 0.0, 0.0]], rtol=1e-14)
    assert springs.energy(model, q) == pytest.approx(0.15, rel=1e-14)
    ball, control = _ball("isothermal")
    data = ref.control_arrays(ball, control)
    assert gas.driving_values(ball, data, 0.025)[0] == pytest.approx(40.0, rel=1e-14)
    v = rvolume.volumes(ball, ball.particle_q)
    assert gas.pressures(ball, data, 0.0, v)[0] == pytest.approx(30.0 / v[0], rel=1e-14)
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    assert rvolume.bounding(cube, rvolume.BOUNDING_BOX) == pytest.approx(1.0, rel=1e-15)
    assert rvolume.bounding(cube, rvolume.BOUNDING_SPHERE) == pytest.approx(
        4.0 / 3.0 * np.pi * (np.sqrt(3.0) / 2.0) ** 3, rel=1e-14
    )


def test_drag_power_is_never_positive_in_still_air():
    """Drag's power sum_t F_t . v_t = -sum_t 1/2 rho C_d A_t |v_rel . n_t|^3 <= 0 with no
    wind (core/terms/drag.hpp), and it equals that closed form."""
    model, _ = _drag_ball()
    control = model.control()
    control.wind = np.zeros(3)
    data = ref.control_arrays(model, control)
    q, qd = _state(model, 4)
    tri = model.tri_indices
    area_n = 0.5 * np.cross(q[tri[:, 1]] - q[tri[:, 0]], q[tri[:, 2]] - q[tri[:, 0]])
    area = np.linalg.norm(area_n, axis=1)
    v = qd[tri].mean(axis=1)
    vn = np.einsum("tk,tk->t", v, area_n) / area
    cd = model.body_drag_coefficient[model.tri_body]
    expected = -np.sum(0.5 * model.air_density * cd * area * np.abs(vn) ** 3)
    assert expected < 0.0
    assert drag.power(model, data, q, qd) == pytest.approx(expected, rel=1e-12)


# -- reference steps of the implicit solvers ---------------------------------------------
def _small() -> tuple[sb.Model, sb.Control, np.ndarray, np.ndarray]:
    """A small ball (42 particles: dense matrices stay small) with a gas and an ambient
    pressure, damping, bending springs, a pinned particle, an attachment, external forces
    and a grab; a deformed, moving start (the pinned particle at rest)."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    gas = sb.Gas.isothermal(25.0, ambient_pressure=10.0)
    b.add_soft_body(sb.icosphere(1, radius=0.3, center=(0.0, 0.5, 0.0)), mass=0.5,
                    stiffness=300.0, damping=0.4, gas=gas, bend_stiffness=10.0,
                    bend_damping=0.05, pinned=[0])  # fmt: skip
    b.add_attachment(5, anchor=(0.0, 1.2, 0.0), stiffness=40.0, damping=0.5, rest_length=0.3)
    model = b.finalize()
    control = model.control()
    control.particle_f[:] = np.random.default_rng(1).normal(0.0, 0.2, control.particle_f.shape)
    control.grab_particle = 20
    control.grab_target = np.array([0.3, 0.9, 0.1])
    control.grab_stiffness, control.grab_damping = 20.0, 0.2
    q, qd = _state(model, 2)
    qd[0] = 0.0
    return model, control, q, qd


def _simulator_step(model, control, q, qd, integrator, dt, **options):
    state = model.state()
    state.particle_q[:], state.particle_qd[:] = q, qd
    sim = sb.Simulator(model, integrator=integrator, dt=dt, **options)
    sim.step(state, control)
    return state, sim


def test_one_backward_euler_step_matches_the_dense_newton_step(simd):
    """One step of Simulator(integrator="implicit_euler") equals the reference's dense
    Newton step (M - h C - h^2 K) dv = h (f0 + K h v0), solved by numpy.linalg.solve: CG
    stops at a residual |r| <= tol |b|, so |dv - dv_ref| <= tol |b| / sigma_min(M - h C -
    h^2 K) (smallest singular value, from the dense matrix), and x1 differs by dt times
    that. The matrix is symmetric to round-off, as CG needs."""
    from softbody.reference import steps

    model, control, q0, v0 = _small()
    dt, tolerance = 5e-3, 1e-12
    state, sim = _simulator_step(model, control, q0, v0, "implicit_euler", dt,
                                 implicit_tolerance=tolerance,
                                 implicit_max_iterations=2000)  # fmt: skip
    expected = steps.backward_euler_step(model, ref.control_arrays(model, control), 0.0, dt,
                                         q0, v0)  # fmt: skip
    # CG's premise: the matrix is symmetric (the closed surface's pressure Hessian too)
    a = expected.matrix
    assert np.abs(a - a.T).max() <= ULPS * EPS * np.abs(a).max()
    sigma_min = np.linalg.svd(a, compute_uv=False)[-1]
    bound = tolerance * np.linalg.norm(expected.rhs) / sigma_min
    bound += ULPS * EPS * np.abs(expected.qd).max()  # the solves' own round-off
    dv = expected.qd - v0
    assert bound < 1e-9 * np.abs(dv).max()  # sharp against the change it checks
    assert np.linalg.norm(state.particle_qd - expected.qd) <= bound
    assert np.linalg.norm(state.particle_q - expected.q) <= dt * bound + ULPS * EPS
    assert sim.solver_iterations[1] > 1  # CG ran


@pytest.mark.parametrize("iterations", [1, 3])
def test_one_projective_step_matches_the_dense_local_global_iterations(iterations, simd):
    """One step of Simulator(integrator="projective") equals the reference's local-global
    iterations with a dense solve of the global matrix: the factored and the dense solve
    agree to round-off amplified by the matrix's condition number, ULPS eps cond(A) |x|
    per iteration (and v1 = (x1 - x0) / dt that divided by dt)."""
    from softbody.reference import steps

    model, control, q0, v0 = _small()
    dt = 5e-3
    state, _ = _simulator_step(model, control, q0, v0, "projective", dt,
                               projective_iterations=iterations)  # fmt: skip
    x, v = steps.projective_step(model, ref.control_arrays(model, control), 0.0, dt, q0, v0,
                                 iterations)  # fmt: skip
    cond = np.linalg.cond(steps.projective_matrix(model, dt))
    bound = iterations * ULPS * EPS * cond * np.abs(x).max()
    assert bound < 1e-6 * np.abs(x - q0).max()  # sharp against the step's motion
    assert np.abs(state.particle_q - x).max() <= bound
    assert np.abs(state.particle_qd - v).max() <= bound / dt + ULPS * EPS * np.abs(v).max()
