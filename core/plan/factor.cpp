// Projective dynamics' factor set-up (factor.hpp). The order is the one the engine's
// first (Numba) version computed, bit for bit (tests/data/dissection-order-*.npy).
#include "plan/factor.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace softbody::plan {

namespace {

/// np.median of values (the mean of the two middle ones for an even count).
double median(std::vector<double>& values, index size) {
    const index half = size / 2;
    auto begin = values.begin(), end = values.begin() + size;
    std::nth_element(begin, begin + half, end);
    const double upper = values[static_cast<size_t>(half)];
    if (size % 2 == 1) return upper;
    const double lower = *std::max_element(begin, begin + half);
    return (lower + upper) / 2;
}

}  // namespace

std::vector<index> dissection_order(index n, const index* indptr, const index* indices,
                                    const double* points, index leaf) {
    std::vector<index> buf(static_cast<size_t>(n)), tmp(static_cast<size_t>(n)),
        stamp(static_cast<size_t>(n), -1), order(static_cast<size_t>(n));
    std::vector<double> vals(static_cast<size_t>(n));
    std::vector<char> upper(static_cast<size_t>(n), 0);
    for (index i = 0; i < n; ++i) buf[static_cast<size_t>(i)] = i;
    struct Task {
        index lo, hi;
        bool emit;
    };
    std::vector<Task> tasks;  // depth first: last pushed, first done
    tasks.push_back({0, n, false});
    index done = 0, cut = 0;
    // whether particle v has a neighbour in the current set's upper half (the set's
    // particles carry the newest stamp)
    auto touches_upper = [&](index v) {
        const index current = stamp[static_cast<size_t>(v)];
        for (index e = indptr[v]; e < indptr[v + 1]; ++e) {
            const index u = indices[e];
            if (stamp[static_cast<size_t>(u)] == current && upper[static_cast<size_t>(u)]) return true;
        }
        return false;
    };
    while (!tasks.empty()) {
        const Task task = tasks.back();
        tasks.pop_back();
        const index lo = task.lo, hi = task.hi, size = hi - lo;
        if (!task.emit && size > leaf) {
            // the widest coordinate of the set, and its median
            int axis = 0;
            double widest = -1.0;
            for (int k = 0; k < 3; ++k) {
                double c_min = std::numeric_limits<double>::infinity();
                double c_max = -std::numeric_limits<double>::infinity();
                for (index r = lo; r < hi; ++r) {
                    const double x = points[3 * buf[static_cast<size_t>(r)] + k];
                    c_min = std::min(c_min, x);
                    c_max = std::max(c_max, x);
                }
                if (c_max - c_min > widest) {
                    axis = k;
                    widest = c_max - c_min;
                }
            }
            for (index r = lo; r < hi; ++r)
                vals[static_cast<size_t>(r - lo)] = points[3 * buf[static_cast<size_t>(r)] + axis];
            const double cut_at = median(vals, size);
            index lows = 0;
            for (index r = lo; r < hi; ++r) {
                const index v = buf[static_cast<size_t>(r)];
                stamp[static_cast<size_t>(v)] = cut;
                upper[static_cast<size_t>(v)] = !(points[3 * v + axis] < cut_at);
                if (!upper[static_cast<size_t>(v)]) ++lows;
            }
            ++cut;
            if (0 < lows && lows < size) {
                // stable partition: lower half off the separator, upper half, separator
                index first = 0;
                for (index r = lo; r < hi; ++r) {
                    const index v = buf[static_cast<size_t>(r)];
                    if (!upper[static_cast<size_t>(v)] && !touches_upper(v)) tmp[static_cast<size_t>(first++)] = v;
                }
                index second = first;
                for (index r = lo; r < hi; ++r) {
                    const index v = buf[static_cast<size_t>(r)];
                    if (upper[static_cast<size_t>(v)]) tmp[static_cast<size_t>(second++)] = v;
                }
                index third = second;
                for (index r = lo; r < hi; ++r) {
                    const index v = buf[static_cast<size_t>(r)];
                    if (!upper[static_cast<size_t>(v)] && touches_upper(v)) tmp[static_cast<size_t>(third++)] = v;
                }
                for (index r = 0; r < size; ++r) buf[static_cast<size_t>(lo + r)] = tmp[static_cast<size_t>(r)];
                tasks.push_back({lo + second, hi, true});
                tasks.push_back({lo + first, lo + second, false});
                tasks.push_back({lo, lo + first, false});
                continue;
            }
            // all at one coordinate: no cut, the set is emitted as it is
        }
        for (index r = lo; r < hi; ++r) order[static_cast<size_t>(done++)] = buf[static_cast<size_t>(r)];
    }
    return order;
}

Csc strict_lower(index n, const index* indptr, const index* indices, const double* data) {
    std::vector<index> row_ptr(static_cast<size_t>(n + 1), 0);
    for (index j = 0; j < n; ++j)
        for (index e = indptr[j]; e < indptr[j + 1]; ++e)
            if (indices[e] > j) ++row_ptr[static_cast<size_t>(indices[e] + 1)];
    for (index i = 0; i < n; ++i) row_ptr[static_cast<size_t>(i + 1)] += row_ptr[static_cast<size_t>(i)];
    const size_t nnz = static_cast<size_t>(row_ptr[static_cast<size_t>(n)]);
    // by row: each row's columns come in increasing order, as the columns are scanned so
    std::vector<index> row_col(nnz), fill(row_ptr.begin(), row_ptr.end() - 1);
    std::vector<double> row_data(nnz);
    Csc out;
    out.indptr.assign(static_cast<size_t>(n + 1), 0);
    for (index j = 0; j < n; ++j)
        for (index e = indptr[j]; e < indptr[j + 1]; ++e) {
            const index i = indices[e];
            if (i > j) {
                const size_t at = static_cast<size_t>(fill[static_cast<size_t>(i)]++);
                row_col[at] = j;
                row_data[at] = data[e];
                ++out.indptr[static_cast<size_t>(j + 1)];
            }
        }
    for (index j = 0; j < n; ++j) out.indptr[static_cast<size_t>(j + 1)] += out.indptr[static_cast<size_t>(j)];
    // and back by column: each column's rows come in increasing order
    out.indices.resize(nnz);
    out.data.resize(nnz);
    fill.assign(out.indptr.begin(), out.indptr.end() - 1);
    for (index i = 0; i < n; ++i)
        for (index e = row_ptr[static_cast<size_t>(i)]; e < row_ptr[static_cast<size_t>(i + 1)]; ++e) {
            const index j = row_col[static_cast<size_t>(e)];
            const size_t at = static_cast<size_t>(fill[static_cast<size_t>(j)]++);
            out.indices[at] = i;
            out.data[at] = row_data[static_cast<size_t>(e)];
        }
    return out;
}

Supernodes supernodes(index n, const index* indptr, const index* indices, const double* data) {
    Supernodes s;
    s.col.push_back(0);
    for (index j = 0; j + 1 < n; ++j) {
        const index a0 = indptr[j], a1 = indptr[j + 1], b0 = indptr[j + 1], b1 = indptr[j + 2];
        bool joins = a1 - a0 == b1 - b0 + 1 && a1 > a0 && indices[a0] == j + 1;
        for (index e = 0; joins && e < b1 - b0; ++e)
            if (indices[a0 + 1 + e] != indices[b0 + e]) joins = false;
        if (!joins) s.col.push_back(j + 1);
    }
    s.col.push_back(n);
    const index count = static_cast<index>(s.col.size()) - 1;
    s.row_ptr.assign(static_cast<size_t>(count + 1), 0);
    s.value_ptr.assign(static_cast<size_t>(count + 1), 0);
    for (index k = 0; k < count; ++k) {
        const index c0 = s.col[static_cast<size_t>(k)], c1 = s.col[static_cast<size_t>(k + 1)];
        const index height = 1 + indptr[c0 + 1] - indptr[c0];  // its first column's diagonal and rows
        s.row_ptr[static_cast<size_t>(k + 1)] = s.row_ptr[static_cast<size_t>(k)] + height;
        s.value_ptr[static_cast<size_t>(k + 1)] = s.value_ptr[static_cast<size_t>(k)] + height * (c1 - c0);
    }
    s.rows.assign(static_cast<size_t>(s.row_ptr.back()), 0);
    s.values.assign(static_cast<size_t>(s.value_ptr.back()), 0.0);
    for (index k = 0; k < count; ++k) {
        const index c0 = s.col[static_cast<size_t>(k)], c1 = s.col[static_cast<size_t>(k + 1)];
        const index width = c1 - c0, r0 = s.row_ptr[static_cast<size_t>(k)], v0 = s.value_ptr[static_cast<size_t>(k)];
        s.rows[static_cast<size_t>(r0)] = c0;
        for (index e = indptr[c0]; e < indptr[c0 + 1]; ++e)
            s.rows[static_cast<size_t>(r0 + 1 + e - indptr[c0])] = indices[e];
        for (index j = c0; j < c1; ++j)
            // column j's rows are the node's rows from j - c0 + 1 on, by construction
            for (index e = indptr[j]; e < indptr[j + 1]; ++e) {
                const index p = j - c0 + 1 + e - indptr[j];
                s.values[static_cast<size_t>(v0 + p * width + j - c0)] = data[e];
            }
    }
    return s;
}

}  // namespace softbody::plan
