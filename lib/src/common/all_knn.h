// All k nearest neighbours of every point of a set (simplify's candidate pairs): a KD-tree with
// buckets of at most kBucket points, queried one bucket at a time. The points of a bucket share
// one traversal of the tree (a node is skipped when its box is farther from each of the bucket's
// points than that point's k-th distance found so far), and each point of a visited bucket is
// measured against all of them at once (a vector loop over the bucket). Exact: squared
// distances in double from the float coordinates (x = double(p) - double(q), then
// x^2 + y^2 + z^2 in that order, as a float64 brute force computes them), ties by the nearer
// index |i - j|, then the smaller, so the lists depend neither on the tree nor on the thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat::detail {

class AllKnnTree {
public:
    /// At most this many points per leaf (and per query batch).
    static constexpr std::size_t kBucket = 16;
    /// The largest k all_knn_leaf answers.
    static constexpr std::size_t kMaxK = 32;

    /// Builds the tree over the n x 3 float array `points` (copied). `fn` names the caller in the
    /// error for more than 2^32 - 1 points (std::invalid_argument).
    AllKnnTree(const float* points, std::size_t n, const char* fn);

    /// Number of leaves; all_knn_leaf(l, ...) for l in [0, leaf_count()) covers every point once,
    /// in an order where consecutive leaves are near in space.
    std::size_t leaf_count() const { return leaves_.size(); }

    /// For every point i of leaf l: its min(k, n - 1) nearest other points (the first in
    /// increasing (squared distance, |i - j|, j)), written to out[i * k ...] in no particular order
    /// (i the point's input index).
    /// k <= kMaxK, else std::invalid_argument. Const: leaves may be queried concurrently.
    void all_knn_leaf(std::size_t l, std::size_t k, std::uint32_t* out) const;

    struct Node {
        double lo[3], hi[3];       // bounding box of the points below (their coordinates, exactly)
        std::uint32_t begin, end;  // range in leaf order
        std::int32_t left = -1, right = -1;
        std::uint32_t min_id, max_id;  // input index range below (ties at the bound are by index)
    };

    /// A point as the build moves it: its coordinates and input index.
    struct BuildPoint {
        float c[3];
        std::uint32_t id;
    };
    /// The build's split (public for its test): reorders a[begin, end) so that a[begin, mid) holds
    /// its mid - begin smallest points by (coordinate `axis`, id), -0 before +0 (begin <= mid <
    /// end). After `max_rounds` rounds of its own quickselect it hands over to std::nth_element.
    static void split(BuildPoint* a, std::size_t begin, std::size_t mid, std::size_t end, int axis,
                      int max_rounds = 64);

private:
    void build(BuildPoint* pts, std::size_t begin, std::size_t end, std::size_t self);

    std::size_t n_;
    std::vector<Node> nodes_;
    std::vector<std::uint32_t> leaves_;  // node index of each leaf, in leaf (spatial) order
    std::vector<std::uint32_t> id_;      // input index of each point, in leaf order
    std::vector<double> x_, y_, z_;      // coordinates in leaf order
};

}  // namespace avsplat::detail
