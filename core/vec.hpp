// A 3-vector of doubles with the algebra the physics terms use. Kernel code only (it is
// compiled once per instruction set, in that build's namespace).
#pragma once

#include "config.hpp"

namespace softbody::SOFTBODY_KERNELS {

struct V3 {
    double x, y, z;
};

inline V3 load(const double* p, index i) { return {p[3 * i], p[3 * i + 1], p[3 * i + 2]}; }
inline void store(double* p, index i, V3 v) {
    p[3 * i] = v.x;
    p[3 * i + 1] = v.y;
    p[3 * i + 2] = v.z;
}
inline void add_to(double* p, index i, V3 v) {
    p[3 * i] += v.x;
    p[3 * i + 1] += v.y;
    p[3 * i + 2] += v.z;
}
inline V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 operator-(V3 a) { return {-a.x, -a.y, -a.z}; }
inline V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 cross(V3 a, V3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline bool finite(double v) { return std::isfinite(v); }

}  // namespace softbody::SOFTBODY_KERNELS
