"""The model's fields are declared once, in ``core/fields.hpp``: the C++ Model's parts,
the binding's reading and checking, and ``softbody._core.model_fields()`` all come from
that table.

Reference: the table itself. Every field it declares is a field of the Python
``softbody.Model`` of the declared type and shape (in the counts N, S, A, T, B, M, K, P,
C, H of the model), on models that have every part (the every-term model, the surface
contacts' two balls, a scene with colliders, a ball and a cloth with material bending,
a ball with mesh colliders);
and a field's declared check refuses a value that breaks it, naming the field.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import softbody as sb
from softbody import _core
from softbody.scenes.loader import load_scene
from trajectory_cases import build_case

FIELDS = _core.model_fields()


def _counts(model: sb.Model) -> dict[str, int]:
    return {
        "N": model.particle_count, "S": model.spring_count, "A": model.attachment_count,
        "T": model.tri_count, "B": model.body_count, "M": len(model.mc_samples),
        "K": len(model.schedule_time), "P": model.pin_count, "C": model.collider_count,
        "V": len(model.vent_body), "O": len(model.orifice_bodies),
        "I": len(model.inflator_body), "Q": len(model.inflator_time),
        "H": len(model.bending_hinges),
        "Tm": model.membrane_count,
        "CV": len(model.collider_mesh_vertices), "CT": len(model.collider_mesh_triangles),
        "CN": len(model.collider_mesh_node_children),
    }  # fmt: skip


def _bending_model() -> sb.Model:
    """A ball and a cloth, each with material bending."""
    b = sb.ModelBuilder()
    b.add_soft_body(sb.icosphere(1), mass=1.0, stiffness=100.0, damping=0.1, gas=10.0,
                    bending=sb.Bending(0.01))  # fmt: skip
    b.add_cloth(sb.rectangle((1.0, 1.0), (3, 3), center=(0.0, 2.0, 0.0)), mass=0.1,
                stiffness=50.0, damping=0.1,
                bending=sb.Bending(0.001, rest_shape="flat"))  # fmt: skip
    return b.finalize()


def _mesh_collider_model() -> sb.Model:
    """A ball above a box and a sphere given as triangle meshes, beside an analytic box."""
    b = sb.ModelBuilder()
    b.add_soft_body(sb.icosphere(1, center=(0.0, 2.0, 0.0)), mass=1.0, stiffness=100.0,
                    damping=0.1, gas=10.0)  # fmt: skip
    b.add_collider(sb.ColliderMesh(sb.box((2.0, 0.5, 2.0))))
    b.add_collider(sb.ColliderBox(center=(3.0, 0.0, 0.0)))
    b.add_collider(sb.ColliderMesh(sb.icosphere(2, center=(-3.0, 0.0, 0.0))))
    return b.finalize()


def _models():
    yield "every-term", build_case("every-term", "midpoint")[0]
    yield "surface-two-balls", build_case("surface-two-balls", "midpoint")[0]
    yield "bouncing-balls", load_scene("bouncing-balls").model
    yield "bending", _bending_model()
    builder = sb.ModelBuilder()
    builder.add_soft_body(sb.icosphere(1), mass=0.1, gas=10.0,
                          membrane=[(sb.Membrane.neo_hookean(1e5, 1e-3), None),
                                    (sb.Membrane.stvk(1e6, 0.3, 1e-4), [0, 5])])  # fmt: skip
    yield "membranes", builder.finalize()
    yield "mesh-colliders", _mesh_collider_model()


def test_python_fields_are_generated_from_the_table():
    """softbody.sim._model_fields (the build's output) is exactly what
    tools/gen_model_fields.py makes from core/fields.hpp now (so a changed table with a
    stale build fails here), and its FIELDS equal what the compiled core declares."""
    import importlib.util

    from softbody.sim import _model_fields

    root = Path(__file__).resolve().parent.parent
    spec = importlib.util.spec_from_file_location("gen", root / "tools" / "gen_model_fields.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    expected = gen.generate((root / "core" / "fields.hpp").read_text())
    assert Path(_model_fields.__file__).read_text() == expected
    core = [(f["name"], f["type"], f["shape"].replace(" ", ""), f["check"], f["unit"])
            for f in FIELDS]  # fmt: skip
    assert list(_model_fields.FIELDS) == core


def test_every_python_model_field_the_core_reads_is_declared_once():
    """Names are unique in the table, and every one is a dataclass field of Model."""
    names = [f["name"] for f in FIELDS]
    assert len(names) == len(set(names))
    python = {f.name for f in dataclasses.fields(sb.Model)}
    assert set(names) <= python, sorted(set(names) - python)


@pytest.mark.parametrize(("name", "model"), list(_models()), ids=[n for n, _ in _models()])
def test_model_fields_have_the_declared_type_and_shape(name, model):
    """Arrays: float64 / int64, C-contiguous, of the declared shape; numbers: Python or
    NumPy scalars of the declared kind; vec3: three float64 numbers."""
    counts = _counts(model)
    for f in FIELDS:
        value = getattr(model, f["name"])
        if f["type"] in ("f64", "i64", "vec3"):
            dims = [d.strip() for d in f["shape"].strip("()").split(",") if d.strip()]
            shape = tuple(counts[d] if d in counts else int(d) for d in dims)
            assert isinstance(value, np.ndarray), f["name"]
            assert value.dtype == (np.int64 if f["type"] == "i64" else np.float64), f["name"]
            assert value.shape == shape, (f["name"], value.shape, shape)
            assert value.flags.c_contiguous, f["name"]
        else:
            kind = float if f["type"] == "f64_value" else int
            assert isinstance(value, kind | np.integer | np.floating), f["name"]
            assert f["shape"] == "()"


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("particle_body", lambda m: np.full_like(m.particle_body, m.body_count),
         "particle_body holds"),
        ("body_particle_range", lambda m: m.body_particle_range[:, ::-1].copy(),
         "body_particle_range row 0 is not a range"),
        ("body_gas_law", lambda m: np.full_like(m.body_gas_law, 7), "body_gas_law holds 7"),
        ("body_drag_coefficient", lambda m: np.full(m.body_count, -1.0),
         "body_drag_coefficient holds -1.0+ at 0; it must be finite and >= 0"),
        ("air_density", lambda m: float("nan"), "air_density holds nan at 0; it must be finite"),
        ("wind", lambda m: np.array([0.0, np.inf, 0.0]), "wind holds inf at 1; it must be finite"),
        ("soft_contact_mode", lambda m: 3, "soft_contact_mode holds 3"),
        ("gravity", lambda m: np.zeros(2), r"gravity must have shape \(3,\)"),
        ("bending_stiffness", lambda m: -m.bending_stiffness,
         "bending_stiffness holds -0.0[0-9]+ at 0; it must be finite and >= 0"),
        ("bending_rest_angle", lambda m: np.full_like(m.bending_rest_angle, np.nan),
         "bending_rest_angle holds nan at 0; it must be finite"),
        ("bending_hinges", lambda m: m.bending_hinges + m.particle_count,
         "bending_hinges holds"),
        ("bending_body", lambda m: np.full_like(m.bending_body, m.body_count),
         "bending_body holds"),
        ("collider_mesh_triangles", lambda m: m.collider_mesh_triangles + 1000,
         "collider_mesh_triangles holds"),
        ("collider_mesh_root", lambda m: np.full_like(m.collider_mesh_root, -1),
         "collider 0 is a mesh collider without a tree"),
        ("collider_mesh_node_children", lambda m: np.zeros_like(m.collider_mesh_node_children),
         "collider_mesh_node_children row 0 must name rows after it"),
        ("collider_mesh_range", lambda m: m.collider_mesh_range[:, ::-1].copy(),
         "collider_mesh_range row 0 is not a range"),
    ],
)  # fmt: skip
def test_a_field_that_breaks_its_declared_check_is_refused(field, value, message):
    """Each kind of declared check (index, range, enumeration, finite and >= 0, finite,
    shape) refuses a bad value with a ValueError naming the field."""
    if field.startswith("bending"):
        model = _bending_model()
    elif field.startswith("collider_mesh"):
        model = _mesh_collider_model()
    else:
        model = build_case("every-term", "midpoint")[0]
    bad = dataclasses.replace(model, **{field: value(model)})
    with pytest.raises(ValueError, match=message):
        _core.Model(bad)
