// The vertex-major tables of a model (model.hpp, Slots): for each group of 8 particles, as
// many slots as its busiest particle needs; every particle's ring of neighbours in fan order
// with its edge springs and faces, its other springs, and the faces of a broken fan. Built
// once per model, from its springs and triangles; the kernels' vertex-major pass
// (solvers/lanes.hpp) reads them.
#pragma once

#include <utility>
#include <vector>

#include "model.hpp"

namespace softbody {

class VertexLayout {
public:
    /// Build the tables from m's springs and triangles and point m.slots at them (this
    /// object owns them: it must outlive m's use).
    void build(Model& m);

private:
    static bool fan_order(const std::vector<std::pair<index, index>>& pairs,
                          std::vector<index>& ring, bool& closed);

    /// The membrane triangles' tables (Slots: ring_membrane ... membrane_rows), after the
    /// rings: `rings` each particle's ring neighbours j_0, j_1, ... and whether it closes.
    void build_membranes(Model& m, const std::vector<std::vector<index>>& rings,
                         const std::vector<char>& closed);

    static constexpr index kGroup = 8;  // the kernels' lane group (simd.hpp)
    std::vector<double> lane_mass_, ring_rest_, ring_k_, ring_c_, ring_face_;
    std::vector<double> spring_rest_, spring_k_, spring_c_;
    std::vector<index> lane_reference_, ring_start_, ring_other_;
    std::vector<index> spring_start_, spring_other_, face_start_, face_next_, face_last_;
    std::vector<double> ring_membrane_, membrane_geometry_, membrane_rows_;
    std::vector<index> ring_membrane_row_, membrane_start_, membrane_next_, membrane_last_,
        membrane_row_;
};

}  // namespace softbody
