// The closed sets the model and the run parameters hold as integers, named once here. Each
// set is an X-macro list of (NAME, value); the C++ names come from it, the bindings export
// it (softbody._core.enums()), and tests/test_enums.py checks that the Python IntEnum of
// the same name (softbody.Integrator, GasLaw, VolumeMethod, ColliderKind, MotionKind,
// softbody.solvers.Status) holds exactly these members, so the two cannot drift apart.
#pragma once

#include "config.hpp"

#define SOFTBODY_ENUM_INTEGRATOR(X)                                                          \
    X(EULER, 0) X(MIDPOINT, 1) X(RK4, 2) X(SYMPLECTIC_EULER, 3) X(VELOCITY_VERLET, 4)      \
    X(IMPLICIT_EULER, 5) X(BDF2, 6) X(PROJECTIVE, 7) X(XPBD, 8)
#define SOFTBODY_ENUM_GAS_LAW(X) X(ISOTHERMAL, 0) X(FIXED_PRESSURE, 1) X(ADIABATIC, 2)
#define SOFTBODY_ENUM_VOLUME_METHOD(X)                                                       \
    X(EXACT, 0) X(BOUNDING_BOX, 1) X(BOUNDING_SPHERE, 2) X(BOUNDING_ELLIPSOID, 3)           \
    X(MONTE_CARLO, 4)
#define SOFTBODY_ENUM_COLLIDER_KIND(X) X(PLANE, 0) X(BOX_CONTAINER, 1) X(SPHERE, 2) X(BOX, 3) X(MESH, 4)
#define SOFTBODY_ENUM_MOTION_KIND(X)                                                         \
    X(STATIC, 0) X(ROTATION, 1) X(TRANSLATION, 2) X(OSCILLATION, 3)
// soft-soft contacts (ModelBuilder.set_soft_contact's mode)
#define SOFTBODY_ENUM_SOFT_CONTACT_MODE(X) X(NONE, 0) X(BOUNDING, 1) X(SURFACE, 2)
// membrane materials (softbody.MembraneMaterial; core/terms/membrane.hpp)
#define SOFTBODY_ENUM_MEMBRANE_MATERIAL(X) X(NEO_HOOKEAN, 0) X(MOONEY_RIVLIN, 1) X(STVK, 2)
#define SOFTBODY_ENUM_STATUS(X)                                                              \
    X(OK, 0) X(NONFINITE, 1) X(RUNAWAY, 2) X(BAD_VOLUME, 3) X(SHRUNK, 4) X(EXPLODED, 5)    \
    X(NEED_HASH, 6) X(STOPPED, 7) X(BAD_GAS, 8) X(CROSSED, 9) X(NEED_PAIRS, 10)

// Every set, with the name of its Python IntEnum.
#define SOFTBODY_ENUMS(X)                                        \
    X(Integrator, "Integrator", SOFTBODY_ENUM_INTEGRATOR)       \
    X(GasLaw, "GasLaw", SOFTBODY_ENUM_GAS_LAW)                  \
    X(VolumeMethod, "VolumeMethod", SOFTBODY_ENUM_VOLUME_METHOD) \
    X(ColliderKind, "ColliderKind", SOFTBODY_ENUM_COLLIDER_KIND) \
    X(MotionKind, "MotionKind", SOFTBODY_ENUM_MOTION_KIND)       \
    X(SoftContactMode, "SoftContactMode", SOFTBODY_ENUM_SOFT_CONTACT_MODE) \
    X(MembraneMaterial, "MembraneMaterial", SOFTBODY_ENUM_MEMBRANE_MATERIAL)

namespace softbody {

// Each set a namespace holding an unscoped enum over `index` (so a model array's entry
// compares with GasLaw::ADIABATIC as it is) and its member count kCount.
#define SOFTBODY_ENUM_MEMBER(name, value) name = value,
#define SOFTBODY_ENUM_ONE(name, value) +1
#define SOFTBODY_DECLARE_ENUM(cpp, python, list)                    \
    namespace cpp {                                                 \
    enum Value : index { list(SOFTBODY_ENUM_MEMBER) };              \
    constexpr index kCount = 0 list(SOFTBODY_ENUM_ONE);             \
    }
SOFTBODY_ENUMS(SOFTBODY_DECLARE_ENUM)
#undef SOFTBODY_DECLARE_ENUM

}  // namespace softbody
