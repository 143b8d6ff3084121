// Shared basics of the engine core: the index type, the per-instruction-set namespace and a
// small 3-vector type, so that the physics reads as vector algebra.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace softbody {

using index = std::int64_t;  // NumPy's int64, the index type of every model array

}  // namespace softbody

// kernels.cpp is compiled once per instruction set with SOFTBODY_ISA set to scalar, avx2 or
// avx512. Every function of the kernel headers lives in softbody::SOFTBODY_KERNELS, a
// namespace of its own per build, so the three copies never meet at link time.
// A kernel helper the compiler must inline (one called at several places in a hot loop,
// whose vector arguments would otherwise go through memory).
#if defined(__GNUC__) || defined(__clang__)
#define SOFTBODY_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define SOFTBODY_ALWAYS_INLINE __forceinline
#endif
#define SOFTBODY_CAT2(a, b) a##b
#define SOFTBODY_CAT(a, b) SOFTBODY_CAT2(a, b)
#ifdef SOFTBODY_ISA
#define SOFTBODY_KERNELS SOFTBODY_CAT(isa_, SOFTBODY_ISA)
#endif
