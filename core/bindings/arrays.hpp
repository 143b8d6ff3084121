// What every binding shares: the array types it takes from NumPy, the checks of their
// shapes, index ranges and layouts (a bad array is a ValueError naming it, before any
// kernel runs), and arrays handed back to NumPy without a copy.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>
#include <vector>

#include "kernels.hpp"
#include "model.hpp"

namespace nb = nanobind;

namespace softbody::bindings {

using Index = softbody::index;

using ConstF64 = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;
using ConstI64 = nb::ndarray<const std::int64_t, nb::c_contig, nb::device::cpu>;
using F64 = nb::ndarray<double, nb::c_contig, nb::device::cpu>;

[[noreturn]] inline void fail(const std::string& what) { throw nb::value_error(what.c_str()); }

inline std::string shape_text(const std::vector<Index>& shape) {
    std::string s = "(";
    for (size_t k = 0; k < shape.size(); ++k) {
        if (k) s += ", ";
        s += std::to_string(shape[k]);
    }
    return s + (shape.size() == 1 ? ",)" : ")");
}

template <typename Array>
void check_shape(const Array& a, const std::string& name, const std::vector<Index>& shape) {
    bool ok = a.ndim() == shape.size();
    for (size_t k = 0; ok && k < shape.size(); ++k)
        ok = shape[k] < 0 || static_cast<Index>(a.shape(k)) == shape[k];
    if (!ok) {
        std::vector<Index> got;
        for (size_t k = 0; k < a.ndim(); ++k) got.push_back(static_cast<Index>(a.shape(k)));
        fail(name + " must have shape " + shape_text(shape) + ", got " + shape_text(got));
    }
}

/// A float64 (or int64) C-contiguous array attribute of a Python bundle, shape-checked.
template <typename Array>
Array attribute(nb::handle bundle, const char* name, const std::vector<Index>& shape) {
    nb::object value = bundle.attr(name);
    Array a;
    if (!nb::try_cast(value, a, false))
        fail(std::string(name) + " must be a C-contiguous " +
             (std::is_same_v<Array, ConstI64> ? "int64" : "float64") + " array");
    check_shape(a, name, shape);
    return a;
}

inline void check_indices(const Index* v, Index count, Index lo, Index hi, const std::string& name) {
    for (Index k = 0; k < count; ++k)
        if (v[k] < lo || v[k] >= hi)
            fail(name + " holds " + std::to_string(v[k]) + " at " + std::to_string(k) +
                 ", outside [" + std::to_string(lo) + ", " + std::to_string(hi) + ")");
}

inline void check_ranges(const Index* r, Index count, Index limit, const std::string& name) {
    for (Index b = 0; b < count; ++b)
        if (r[2 * b] < 0 || r[2 * b] > r[2 * b + 1] || r[2 * b + 1] > limit)
            fail(name + " row " + std::to_string(b) + " is not a range within [0, " +
                 std::to_string(limit) + "]");
}

inline F64 writable(nb::handle h, const char* name, const std::vector<Index>& shape) {
    F64 a;
    if (!nb::try_cast(h, a, false))
        fail(std::string(name) + " must be a writable C-contiguous float64 array");
    check_shape(a, name, shape);
    return a;
}

/// A vector handed to NumPy without a copy: the array owns it.
template <typename T>
nb::ndarray<nb::numpy, T> to_numpy(std::vector<T>&& v) {
    auto* owned = new std::vector<T>(std::move(v));
    nb::capsule owner(owned, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    size_t shape[1] = {owned->size()};
    return nb::ndarray<nb::numpy, T>(owned->data(), 1, shape, owner);
}

}  // namespace softbody::bindings
