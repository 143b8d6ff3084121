// Projective dynamics' factor set-up (core/plan/factor.hpp): the dissection order, the
// strict lower part and the supernodes, from checked sparse patterns.
#include "bindings/bindings.hpp"
#include "bindings/arrays.hpp"
#include "plan/factor.hpp"

namespace softbody::bindings {
namespace {

/// A CSR or CSC index structure of an (n, n) matrix: indptr (n + 1,) from 0, not
/// decreasing, to len(indices); every index in [0, n).
Index checked_pattern(ConstI64 indptr, ConstI64 indices, const char* what) {
    check_shape(indptr, std::string(what) + " indptr", {-1});
    check_shape(indices, std::string(what) + " indices", {-1});
    const Index n = static_cast<Index>(indptr.shape(0)) - 1;
    if (n < 1) fail(std::string(what) + ": the matrix is empty");
    const Index* p = indptr.data();
    if (p[0] != 0 || p[n] != static_cast<Index>(indices.shape(0)))
        fail(std::string(what) + " indptr must run from 0 to the number of entries");
    for (Index k = 0; k < n; ++k)
        if (p[k + 1] < p[k]) fail(std::string(what) + " indptr decreases");
    check_indices(indices.data(), p[n], 0, n, std::string(what) + " indices");
    return n;
}

nb::ndarray<nb::numpy, Index> plan_dissection_order(ConstI64 indptr, ConstI64 indices,
                                                    ConstF64 points, Index leaf) {
    const Index n = checked_pattern(indptr, indices, "pattern");
    check_shape(points, "points", {n, 3});
    if (leaf < 1) fail("leaf must be >= 1");
    std::vector<Index> order;
    {
        nb::gil_scoped_release release;
        order = softbody::plan::dissection_order(n, indptr.data(), indices.data(),
                                                 points.data(), leaf);
    }
    return to_numpy(std::move(order));
}

nb::tuple plan_strict_lower(ConstI64 indptr, ConstI64 indices, ConstF64 data) {
    const Index n = checked_pattern(indptr, indices, "factor");
    check_shape(data, "factor data", {static_cast<Index>(indices.shape(0))});
    softbody::plan::Csc out;
    {
        nb::gil_scoped_release release;
        out = softbody::plan::strict_lower(n, indptr.data(), indices.data(), data.data());
    }
    return nb::make_tuple(to_numpy(std::move(out.indptr)), to_numpy(std::move(out.indices)),
                          to_numpy(std::move(out.data)));
}

nb::tuple plan_supernodes(ConstI64 indptr, ConstI64 indices, ConstF64 data) {
    const Index n = checked_pattern(indptr, indices, "factor");
    check_shape(data, "factor data", {static_cast<Index>(indices.shape(0))});
    for (Index j = 0; j < n; ++j)
        for (Index e = indptr.data()[j]; e < indptr.data()[j + 1]; ++e)
            if (indices.data()[e] <= j) fail("the factor must be strictly lower triangular");
    softbody::plan::Supernodes s;
    {
        nb::gil_scoped_release release;
        s = softbody::plan::supernodes(n, indptr.data(), indices.data(), data.data());
    }
    return nb::make_tuple(to_numpy(std::move(s.col)), to_numpy(std::move(s.row_ptr)),
                          to_numpy(std::move(s.rows)), to_numpy(std::move(s.value_ptr)),
                          to_numpy(std::move(s.values)));
}

}  // namespace

void bind_plan(nb::module_& mod) {
    mod.def("plan_dissection_order", &plan_dissection_order, nb::arg("indptr").noconvert(),
            nb::arg("indices").noconvert(), nb::arg("points").noconvert(), nb::arg("leaf"),
            "Nested-dissection order (n,) of the CSR pattern of an (n, n) matrix, from "
            "points (n, 3).");
    mod.def("plan_strict_lower", &plan_strict_lower, nb::arg("indptr").noconvert(),
            nb::arg("indices").noconvert(), nb::arg("data").noconvert(),
            "(indptr, indices, data): the strictly lower part of a lower triangular CSC "
            "matrix, rows sorted in each column.");
    mod.def("plan_supernodes", &plan_supernodes, nb::arg("indptr").noconvert(),
            nb::arg("indices").noconvert(), nb::arg("data").noconvert(),
            "(col, row_ptr, rows, value_ptr, values): the supernodes of a strictly lower "
            "CSC factor with sorted rows.");
}

}  // namespace softbody::bindings
