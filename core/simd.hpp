// Lanes of doubles for the vertex-major kernels: kLanes particles at once (8 with AVX-512,
// 4 with AVX2, 1 on the scalar path), as GCC/Clang vector types so that the physics is
// written once; only the square root and the load of neighbour rows (an in-register
// transpose) are written per instruction set. Lane arithmetic is plain IEEE arithmetic, the
// same on every path, so all paths give the same bits.
#pragma once

#include <cstring>
#include <type_traits>

#include "config.hpp"

// A variant compiled without its instruction set would quietly be the scalar code under
// another name: the build's flags (CMakeLists.txt) must turn it on.
#if defined(SOFTBODY_ISA_avx2) && !(defined(__AVX2__) && defined(__FMA__))
#error "the avx2 kernels need AVX2 and FMA enabled (-mavx2 -mfma, or /arch:AVX2)"
#endif
#if defined(SOFTBODY_ISA_avx512) && !(defined(__AVX512F__) && defined(__AVX512DQ__) && \
                                      defined(__AVX512VL__))
#error "the avx512 kernels need AVX-512 F, DQ and VL enabled (-mavx512f ..., or /arch:AVX512)"
#endif

#if defined(__AVX512F__) || defined(__AVX2__)
#include <immintrin.h>
#endif

namespace softbody::SOFTBODY_KERNELS {

#if defined(__AVX512F__)
constexpr int kLanes = 8;
#elif defined(__AVX2__)
constexpr int kLanes = 4;
#else
constexpr int kLanes = 1;
#endif

/// The layout's lane group: particles are grouped by 8 whatever the instruction set, so
/// the neighbour tables (and the order of every sum) do not depend on it.
constexpr int kGroup = 8;
/// Doubles per particle row in the packed state: x, y, z, vx, vy, vz and two of padding
/// (one 64-byte line per particle).
constexpr int kRow = 8;

typedef double vd __attribute__((vector_size(sizeof(double) * kLanes)));
typedef std::int64_t vi __attribute__((vector_size(sizeof(double) * kLanes)));

inline vd splat(double x) { return vd{} + x; }

inline vd load_lanes(const double* p) {
    vd v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

inline void store_lanes(double* p, vd v) { std::memcpy(p, &v, sizeof v); }

inline vd vsqrt(vd x) {
#if defined(__AVX512F__)
    return _mm512_sqrt_pd(x);
#elif defined(__AVX2__)
    return _mm256_sqrt_pd(x);
#else
    return vd{std::sqrt(x[0])};
#endif
}

/// a b + c per lane: rounded once (FMA) with AVX2 and AVX-512, a b then + c on the scalar
/// path (whose kernels are built without FMA).
inline vd fmadd(vd a, vd b, vd c) {
#if defined(__AVX512F__)
    return _mm512_fmadd_pd(a, b, c);
#elif defined(__AVX2__)
    return _mm256_fmadd_pd(a, b, c);
#else
    return a * b + c;
#endif
}

/// 1 / sqrt(x) per lane. AVX-512: the 14-bit estimate refined by two Newton steps (each
/// doubles the correct bits: 28, then past double precision), so within a few ulp of the
/// correctly rounded value, without the divide and square root that cost ~20 cycles each
/// per 8 lanes (measured: half of the force pass). AVX2 and scalar: 1 / sqrt(x), rounded.
/// x = 0 gives infinity or NaN; callers mask those lanes.
inline vd vrsqrt(vd x) {
#if defined(__AVX512F__)
    const vd y0 = _mm512_rsqrt14_pd(x);
    const vd half_x = 0.5 * x;
    const vd y1 = y0 * (1.5 - half_x * y0 * y0);
    return y1 * (1.5 - half_x * y1 * y1);
#else
    return splat(1.0) / vsqrt(x);
#endif
}

// Lanes of floats for the float32 force pass (LaneBuffers.rows_f): 8 particles at once in a
// 256-bit register on AVX2 and AVX-512 alike (on Zen 4 two 256-bit operations issue per
// cycle, twice the lanes of one 512-bit double operation), 1 on the scalar path.
#if defined(__AVX512F__) || defined(__AVX2__)
constexpr int kLanesF = 8;
#else
constexpr int kLanesF = 1;
#endif

typedef float vf __attribute__((vector_size(sizeof(float) * kLanesF)));
typedef std::int32_t vfi __attribute__((vector_size(sizeof(float) * kLanesF)));

inline vf splatf(float x) { return vf{} + x; }

/// x in every lane of a vector of type V (doubles or floats), rounded to its element type.
template <class V>
inline V lanes_of(double x) {
    using T = std::remove_reference_t<decltype(V{}[0])>;
    return V{} + static_cast<T>(x);
}

inline vf load_lanes_f(const float* p) {
    vf v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

/// 1 / sqrt(x) per float lane: the 12-bit estimate and one Newton step (about 23 correct
/// bits, float precision); scalar: 1 / sqrt(x), rounded. Callers mask x = 0.
inline vf vrsqrt(vf x) {
#if defined(__AVX512F__) || defined(__AVX2__)
    const vf y = _mm256_rsqrt_ps(x);
    return y * (1.5f - (0.5f * x) * y * y);
#else
    return vf{1.0f / std::sqrt(x[0])};
#endif
}

/// Where a float lane's mask is set, a; else 0.
inline vf select(vfi mask, vf a) { return mask ? a : vf{}; }

/// Six float lanes of a particle row each: positions (body-local) and velocities.
struct RowsF {
    vf x, y, z, vx, vy, vz;
};

/// The float rows (8 floats each: x, y, z, vx, vy, vz, 0, 0) of particles idx[0 ..
/// kLanesF-1], one lane each: an 8 x 8 transpose in registers.
inline RowsF load_rows_f(const float* rows, const index* idx) {
#if defined(__AVX512F__) || defined(__AVX2__)
    __m256 r[8];
    for (int l = 0; l < 8; ++l) r[l] = _mm256_loadu_ps(rows + 8 * idx[l]);
    const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
    const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
    const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
    const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
    // s_k: element k (and k + 4 in the upper half) of rows 0-3, likewise u_k of rows 4-7
    const __m256 s0 = _mm256_shuffle_ps(t0, t2, 0x44), s1 = _mm256_shuffle_ps(t0, t2, 0xEE);
    const __m256 s2 = _mm256_shuffle_ps(t1, t3, 0x44), s3 = _mm256_shuffle_ps(t1, t3, 0xEE);
    const __m256 u0 = _mm256_shuffle_ps(t4, t6, 0x44), u1 = _mm256_shuffle_ps(t4, t6, 0xEE);
    const __m256 u2 = _mm256_shuffle_ps(t5, t7, 0x44), u3 = _mm256_shuffle_ps(t5, t7, 0xEE);
    return {_mm256_permute2f128_ps(s0, u0, 0x20), _mm256_permute2f128_ps(s1, u1, 0x20),
            _mm256_permute2f128_ps(s2, u2, 0x20), _mm256_permute2f128_ps(s3, u3, 0x20),
            _mm256_permute2f128_ps(s0, u0, 0x31), _mm256_permute2f128_ps(s1, u1, 0x31)};
#else
    const float* r = rows + 8 * idx[0];
    return {vf{r[0]}, vf{r[1]}, vf{r[2]}, vf{r[3]}, vf{r[4]}, vf{r[5]}};
#endif
}

/// Where a lane's mask is set, a; else 0.
inline vd select(vi mask, vd a) { return mask ? a : vd{}; }

/// Six lanes of a particle row each: positions and velocities.
struct Rows {
    vd x, y, z, vx, vy, vz;
};

/// The rows (kRow doubles each) of particles idx[0 .. kLanes-1], one lane each.
SOFTBODY_ALWAYS_INLINE Rows load_rows(const double* rows, const index* idx) {
#if defined(__AVX512F__)
    __m512d r[8];
    for (int l = 0; l < 8; ++l) r[l] = _mm512_loadu_pd(rows + kRow * idx[l]);
    // 8 x 8 transpose: pairs, then 128-bit blocks, then 256-bit halves
    const __m512d t0 = _mm512_unpacklo_pd(r[0], r[1]), t1 = _mm512_unpackhi_pd(r[0], r[1]);
    const __m512d t2 = _mm512_unpacklo_pd(r[2], r[3]), t3 = _mm512_unpackhi_pd(r[2], r[3]);
    const __m512d t4 = _mm512_unpacklo_pd(r[4], r[5]), t5 = _mm512_unpackhi_pd(r[4], r[5]);
    const __m512d t6 = _mm512_unpacklo_pd(r[6], r[7]), t7 = _mm512_unpackhi_pd(r[6], r[7]);
    const __m512d u0 = _mm512_shuffle_f64x2(t0, t2, 0x88), u1 = _mm512_shuffle_f64x2(t0, t2, 0xDD);
    const __m512d u2 = _mm512_shuffle_f64x2(t1, t3, 0x88), u3 = _mm512_shuffle_f64x2(t1, t3, 0xDD);
    const __m512d u4 = _mm512_shuffle_f64x2(t4, t6, 0x88), u5 = _mm512_shuffle_f64x2(t4, t6, 0xDD);
    const __m512d u6 = _mm512_shuffle_f64x2(t5, t7, 0x88), u7 = _mm512_shuffle_f64x2(t5, t7, 0xDD);
    return {_mm512_shuffle_f64x2(u0, u4, 0x88), _mm512_shuffle_f64x2(u2, u6, 0x88),
            _mm512_shuffle_f64x2(u1, u5, 0x88), _mm512_shuffle_f64x2(u3, u7, 0x88),
            _mm512_shuffle_f64x2(u0, u4, 0xDD), _mm512_shuffle_f64x2(u2, u6, 0xDD)};
#elif defined(__AVX2__)
    __m256d lo[4], hi[4];
    for (int l = 0; l < 4; ++l) {
        lo[l] = _mm256_loadu_pd(rows + kRow * idx[l]);
        hi[l] = _mm256_loadu_pd(rows + kRow * idx[l] + 4);
    }
    const __m256d a0 = _mm256_unpacklo_pd(lo[0], lo[1]), a1 = _mm256_unpackhi_pd(lo[0], lo[1]);
    const __m256d a2 = _mm256_unpacklo_pd(lo[2], lo[3]), a3 = _mm256_unpackhi_pd(lo[2], lo[3]);
    const __m256d b0 = _mm256_unpacklo_pd(hi[0], hi[1]), b1 = _mm256_unpackhi_pd(hi[0], hi[1]);
    const __m256d b2 = _mm256_unpacklo_pd(hi[2], hi[3]), b3 = _mm256_unpackhi_pd(hi[2], hi[3]);
    return {_mm256_permute2f128_pd(a0, a2, 0x20), _mm256_permute2f128_pd(a1, a3, 0x20),
            _mm256_permute2f128_pd(a0, a2, 0x31), _mm256_permute2f128_pd(a1, a3, 0x31),
            _mm256_permute2f128_pd(b0, b2, 0x20), _mm256_permute2f128_pd(b1, b3, 0x20)};
#else
    const double* r = rows + kRow * idx[0];
    return {vd{r[0]}, vd{r[1]}, vd{r[2]}, vd{r[3]}, vd{r[4]}, vd{r[5]}};
#endif
}

}  // namespace softbody::SOFTBODY_KERNELS
