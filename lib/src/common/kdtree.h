// A KD-tree over an n x 3 float32 point array (nanoflann), shared by the point-map converter
// (kNN scales) and the geometry metrics (nearest distances).
#pragma once

// <cstdint> before nanoflann: Debian 12's nanoflann 1.4.3 names uint32_t without including it,
// and GCC 13's standard headers no longer bring it in (the build failed there, on Ubuntu 24.04).
#include <cstddef>
#include <cstdint>

#include <nanoflann.hpp>

#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat::detail {

// nanoflann's dataset interface over an n x 3 float32 array.
struct PointArray {
    const float* data;
    std::size_t n;
    std::size_t kdtree_get_point_count() const { return n; }
    float kdtree_get_pt(std::size_t i, std::size_t dim) const { return data[3 * i + dim]; }
    template <class BBox>
    bool kdtree_get_bbox(BBox&) const { return false; }
};

// A KD-tree over n points. Squared distances are accumulated in double so that they match a
// float64 brute-force reference to rounding of the float32 coordinates. Queries are const and
// may run concurrently.
class KdTree {
public:
    KdTree(const float* points, std::size_t n, const char* fn) : points_{points, n} {
        if (n >= std::numeric_limits<std::uint32_t>::max())
            throw std::invalid_argument(std::string(fn) + ": more than 2^32 - 1 points");
        index_.buildIndex();
    }
    // The min(k, n) nearest points to q, nearest first; returns their count.
    std::size_t knn(const float* q, std::size_t k, std::uint32_t* idx, double* d2) const {
        return index_.knnSearch(q, k, idx, d2);
    }
    // The point indices in the tree's leaf order (a permutation of 0..n-1 in which neighbouring
    // entries are near in space): queries in this order find their leaves in the cache.
    const std::vector<std::uint32_t>& leaf_order() const { return index_.vAcc; }

private:
    using Index = nanoflann::KDTreeSingleIndexAdaptor<
        nanoflann::L2_Simple_Adaptor<float, PointArray, double>, PointArray, 3, std::uint32_t>;
    PointArray points_;
    // Built explicitly in the constructor body, after the size check.
    Index index_{3, points_,
                 nanoflann::KDTreeSingleIndexAdaptorParams(
                     10, nanoflann::KDTreeSingleIndexAdaptorFlags::SkipInitialBuildIndex)};
};

}  // namespace avsplat::detail
