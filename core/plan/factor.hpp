// Set-up of projective dynamics' factored matrix (run once per step size, not per step):
// the nested-dissection order of the particles, the strictly lower part of the factor with
// sorted rows, and its supernodes. The Python side (softbody.solvers.factor) builds
// the matrix and factors it with SciPy; bindings/plan.cpp checks the arrays given here.
#pragma once

#include <vector>

#include "config.hpp"

namespace softbody::plan {

/// Nested-dissection order (the particle at each position) of a matrix whose CSR pattern is
/// indptr (n + 1,), indices, from points (n, 3): a set is cut at the median of its widest
/// coordinate, the lower half's particles joined to the upper half by an entry form the
/// separator, ordered after both halves (which are ordered the same way first); sets of at
/// most `leaf` particles are not cut.
std::vector<index> dissection_order(index n, const index* indptr, const index* indices,
                                    const double* points, index leaf);

/// The strictly lower part of a lower triangular CSC matrix with rows sorted in each column.
struct Csc {
    std::vector<index> indptr, indices;
    std::vector<double> data;
};
Csc strict_lower(index n, const index* indptr, const index* indices, const double* data);

/// Columns of a strictly lower CSC factor (rows sorted) grouped into supernodes: column j + 1
/// joins j's node when j's rows are j + 1 and then exactly j + 1's rows. Each node stores its
/// rows (its first column's diagonal, then that column's rows) and a dense block of values
/// (rows x columns, row-major).
struct Supernodes {
    std::vector<index> col, row_ptr, rows, value_ptr;
    std::vector<double> values;
};
Supernodes supernodes(index n, const index* indptr, const index* indices, const double* data);

}  // namespace softbody::plan
