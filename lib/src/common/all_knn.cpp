// AllKnnTree (all_knn.h): the build and the per-leaf query.
#include "common/all_knn.h"

#include "common/cpu_dispatch.h"
#include "common/order_key.h"
#include "common/parallel.h"

#include <omp.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace avsplat::detail {

namespace {

using Node = AllKnnTree::Node;
constexpr std::size_t kB = AllKnnTree::kBucket;

// Squared distance between two boxes (orders the children of a node: the nearer first).
double box_box_d2(const Node& a, const Node& b) {
    double s = 0.0;
    for (int d = 0; d < 3; ++d) {
        const double g = std::max({a.lo[d] - b.hi[d], 0.0, b.lo[d] - a.hi[d]});
        s += g * g;
    }
    return s;
}

// A candidate neighbour j of query i as one integer that orders as (squared distance, |i - j|, j):
// the bits of a non-negative double order as its value. Ties go to the nearest index: rows in
// canonical order put equal Gaussians side by side, and a cloud of many equal points then gets
// neighbour lists that pair it up (by the smallest indices, every list named the same 17 points,
// so a round could merge only 8 pairs).
using Key = unsigned __int128;
inline Key key_of(double d2, std::uint32_t i, std::uint32_t j) {
    std::uint64_t bits;
    std::memcpy(&bits, &d2, sizeof bits);
    const std::uint32_t gap = i > j ? i - j : j - i;
    return (Key(bits) << 64) | (Key(gap) << 32) | j;
}

// The best k of each of the kB queries, sorted; worst[q] is the k-th distance once there are k
// (else +inf), an upper bound of the true k-th. Query lanes past the leaf's size hold NaN
// coordinates: never accepted.
struct Batch {
    double qx[kB], qy[kB], qz[kB];
    double worst[kB];
    std::uint32_t qi[kB];
    Key best[kB][AllKnnTree::kMaxK];
    std::size_t count[kB];
    std::size_t k;

    void insert(std::size_t q, double d2, std::uint32_t j) {
        const Key key = key_of(d2, qi[q], j);
        Key* bk = best[q];
        std::size_t c = count[q];
        if (c == k) {
            if (key > bk[k - 1]) return;
            --c;
        }
        while (c > 0 && bk[c - 1] > key) {
            bk[c] = bk[c - 1];
            --c;
        }
        bk[c] = key;
        if (count[q] < k) ++count[q];
        if (count[q] == k) worst[q] = d2_of(bk[k - 1]);
    }
    static std::uint32_t index_of(Key key) { return std::uint32_t(key); }
    static std::uint32_t gap_of(Key key) { return std::uint32_t(key >> 32); }
    static double d2_of(Key key) {
        const std::uint64_t bits = std::uint64_t(key >> 64);
        double d;
        std::memcpy(&d, &bits, sizeof d);
        return d;
    }
};

// Four doubles in GCC's vector extension (one AVX register in the x86-64-v3 clone, two SSE2 ones
// in the baseline); each lane does the scalar operations, so the distances have the same bits.
typedef double Double4 __attribute__((vector_size(32)));
typedef std::int64_t Long4 __attribute__((vector_size(32)));
constexpr std::size_t kLanes = kB / 4;
static_assert(kB % 4 == 0, "the bucket is a whole number of vectors of four queries");

// Bit l set where lane l of a vector comparison holds (all ones).
__attribute__((always_inline)) inline unsigned lane_mask(const Long4& m) {
#if defined(__SSE2__)
    __m128d lo, hi;
    std::memcpy(&lo, &m, sizeof lo);
    std::memcpy(&hi, reinterpret_cast<const char*>(&m) + sizeof lo, sizeof hi);
    return unsigned(_mm_movemask_pd(lo)) | (unsigned(_mm_movemask_pd(hi)) << 2);
#else
    return unsigned(m[0] & 1) | unsigned(m[1] & 1) << 1 | unsigned(m[2] & 1) << 2 | unsigned(m[3] & 1) << 3;
#endif
}

// Every point of [begin, end) against the kB queries at once (four vectors of four queries), then
// the few accepted (d2 <= worst, not the query itself) inserted one by one. Most points are
// accepted by no query: one test of the four compare masks skips them; the others visit only the
// lanes set in the 16-bit mask of the compares (a branch per lane mispredicted often: 20 % of
// the search). (Written as a scalar loop with a bit mask, GCC did not vectorise it.)
AVSPLAT_CLONES_V3
void scan_leaf(Batch& b, const double* x, const double* y, const double* z, const std::uint32_t* id,
               std::size_t begin, std::size_t end) {
    Double4 qx[kLanes], qy[kLanes], qz[kLanes], worst[kLanes];
    std::memcpy(qx, b.qx, sizeof qx);
    std::memcpy(qy, b.qy, sizeof qy);
    std::memcpy(qz, b.qz, sizeof qz);
    std::memcpy(worst, b.worst, sizeof worst);
    for (std::size_t t = begin; t < end; ++t) {
        const Double4 px = {x[t], x[t], x[t], x[t]}, py = {y[t], y[t], y[t], y[t]}, pz = {z[t], z[t], z[t], z[t]};
        alignas(32) Double4 d2[kLanes];
        unsigned hits = 0;
        for (std::size_t v = 0; v < kLanes; ++v) {
            const Double4 dx = px - qx[v], dy = py - qy[v], dz = pz - qz[v];
            d2[v] = dx * dx + dy * dy + dz * dz;
            hits |= lane_mask(d2[v] <= worst[v]) << (4 * v);
        }
        if (hits == 0) continue;
        const std::uint32_t j = id[t];
        const double* dq = reinterpret_cast<const double*>(d2);
        double* wq = reinterpret_cast<double*>(worst);
        do {
            const unsigned q = unsigned(__builtin_ctz(hits));
            hits &= hits - 1;
            if (j == b.qi[q]) continue;
            b.insert(q, dq[q], j);
            wq[q] = b.worst[q];
        } while (hits != 0);
    }
}

// Per lane, the distance from q to the interval [lo, hi] on one axis: max(lo - q, q - hi, 0).
__attribute__((always_inline)) inline void axis_gap(const Double4& lo, const Double4& hi, const Double4& q,
                                                    Double4& gap) {
    const Double4 zero = {0.0, 0.0, 0.0, 0.0};
    const Double4 a = lo - q, c = q - hi;
    const Double4 g = a > c ? a : c;
    gap = g > zero ? g : zero;
}

// Whether node v can hold a neighbour of some query of the batch: one nearer to the query than
// its k-th, or as near with an index that wins the tie (the index test keeps clouds of many equal
// points from visiting every leaf: n^2 work for n coincident means). Each query's squared
// distance to the box, from axis gaps computed like the point distances, is never above the
// computed distance of a point inside (rounding is monotonic), so the test is exact. Per query,
// not the batch's box against its largest k-th: a batch holding one floater (a large k-th)
// scanned every leaf within the floater's reach for all sixteen queries (twice the points on
// the reduction report's scenes). Padding lanes have worst = -inf and never reach.
AVSPLAT_CLONES_V3
bool reaches(const Batch& b, const Node& v) {
    const Double4 lx = {v.lo[0], v.lo[0], v.lo[0], v.lo[0]}, ly = {v.lo[1], v.lo[1], v.lo[1], v.lo[1]},
                  lz = {v.lo[2], v.lo[2], v.lo[2], v.lo[2]};
    const Double4 hx = {v.hi[0], v.hi[0], v.hi[0], v.hi[0]}, hy = {v.hi[1], v.hi[1], v.hi[1], v.hi[1]},
                  hz = {v.hi[2], v.hi[2], v.hi[2], v.hi[2]};
    Double4 d[kLanes];
    Long4 below = {0, 0, 0, 0}, equal = {0, 0, 0, 0};
    for (std::size_t l = 0; l < kLanes; ++l) {
        Double4 qx, qy, qz, w;
        std::memcpy(&qx, b.qx + 4 * l, sizeof qx);
        std::memcpy(&qy, b.qy + 4 * l, sizeof qy);
        std::memcpy(&qz, b.qz + 4 * l, sizeof qz);
        std::memcpy(&w, b.worst + 4 * l, sizeof w);
        Double4 gx, gy, gz;
        axis_gap(lx, hx, qx, gx);
        axis_gap(ly, hy, qy, gy);
        axis_gap(lz, hz, qz, gz);
        d[l] = gx * gx + gy * gy + gz * gz;
        below |= d[l] < w;
        equal |= d[l] == w;
    }
    if ((below[0] | below[1] | below[2] | below[3]) != 0) return true;
    if ((equal[0] | equal[1] | equal[2] | equal[3]) == 0) return false;
    for (std::size_t q = 0; q < kB; ++q) {
        if (!(d[q / 4][q % 4] == b.worst[q]) || b.count[q] < b.k) continue;
        // The smallest |i - j| over the node's index range [min_id, max_id] (a lower bound over
        // its indices); the k-th's (gap, index) must be beatable.
        const std::uint32_t i = b.qi[q];
        const std::uint32_t g = i < v.min_id ? v.min_id - i : (i > v.max_id ? i - v.max_id : 0u);
        const Key kth = b.best[q][b.k - 1];
        if (g < Batch::gap_of(kth) || (g == Batch::gap_of(kth) && v.min_id < Batch::index_of(kth))) return true;
    }
    return false;
}

}  // namespace

namespace {

// The split of a range of c > kBucket points: the left part holds half of the buckets the range
// needs, rounded up, so every leaf but the last is full.
std::size_t left_size(std::size_t c) {
    const std::size_t buckets = (c + kB - 1) / kB;
    return kB * ((buckets + 1) / 2);
}

// Nodes of the subtree over c points (the tree's shape depends on the count only).
std::size_t subtree_nodes(std::size_t c) {
    if (c <= kB) return 1;
    const std::size_t l = left_size(c);
    return 1 + subtree_nodes(l) + subtree_nodes(c - l);
}

// Ranges above this many points build their halves as parallel tasks.
constexpr std::size_t kTaskMin = 16384;

}  // namespace

// The key is (coordinate on `axis`, index) as one integer (float_order_key above the index). A
// quickselect whose partition has no data-dependent branch (Lomuto's, with a conditional
// advance): std::nth_element's partition mispredicted about every other comparison, most of the
// build. Median-of-three pivots; after max_rounds rounds (adversarial inputs), std::nth_element.
void AllKnnTree::split(BuildPoint* a, std::size_t begin, std::size_t mid, std::size_t end, int axis, int max_rounds) {
    auto key = [axis](const BuildPoint& p) { return (std::uint64_t(float_order_key(p.c[axis])) << 32) | p.id; };
    std::size_t lo = begin, hi = end;  // lo <= mid < hi; before lo all smaller, from hi all larger
    for (int rounds = 0; hi - lo > kB && rounds < max_rounds; ++rounds) {
        const std::size_t m = lo + (hi - lo) / 2;
        const std::uint64_t k0 = key(a[lo]), k1 = key(a[m]), k2 = key(a[hi - 1]);
        const std::size_t p = (k0 < k1) == (k1 < k2) ? m : ((k1 < k0) == (k0 < k2) ? lo : hi - 1);
        std::swap(a[p], a[hi - 1]);
        const std::uint64_t pivot = key(a[hi - 1]);
        std::size_t lt = lo;
        for (std::size_t i = lo; i + 1 < hi; ++i) {
            const BuildPoint t = a[i];
            const bool less = key(t) < pivot;
            a[i] = a[lt];
            a[lt] = t;
            lt += less;
        }
        std::swap(a[lt], a[hi - 1]);  // the pivot, at its place
        if (mid == lt) return;
        if (mid < lt)
            hi = lt;
        else
            lo = lt + 1;
    }
    std::nth_element(a + lo, a + mid, a + hi,
                     [&key](const BuildPoint& x, const BuildPoint& y) { return key(x) < key(y); });
}

AllKnnTree::AllKnnTree(const float* points, std::size_t n, const char* fn) : n_(n) {
    if (n >= std::numeric_limits<std::uint32_t>::max())
        throw std::invalid_argument(std::string(fn) + ": more than 2^32 - 1 points");
    // The points with their indices side by side: the build partitions them in place (no gather
    // through an index array in its comparisons and boxes).
    std::vector<BuildPoint> pts(n);
    for (std::size_t i = 0; i < n; ++i)
        pts[i] = BuildPoint{{points[3 * i], points[3 * i + 1], points[3 * i + 2]}, std::uint32_t(i)};
    if (n > 0) {
        nodes_.resize(subtree_nodes(n));
#pragma omp parallel num_threads(threads_for(n))
#pragma omp single
        build(pts.data(), 0, n, 0);
    }
    id_.resize(n);
    x_.resize(n);
    y_.resize(n);
    z_.resize(n);
    for (std::size_t t = 0; t < n; ++t) {
        id_[t] = pts[t].id;
        x_[t] = double(pts[t].c[0]);
        y_[t] = double(pts[t].c[1]);
        z_[t] = double(pts[t].c[2]);
    }
    for (std::size_t v = 0; v < nodes_.size(); ++v)
        if (nodes_[v].left < 0) leaves_.push_back(std::uint32_t(v));
}

// Node `self` (in preorder) over pts[begin, end): its box, and unless it is a leaf, the split at
// the widest axis (split, ties by index, so the tree is a function of the points) and its
// two children. Allocation-free, so no exception leaves the parallel region.
void AllKnnTree::build(BuildPoint* pts, std::size_t begin, std::size_t end, std::size_t self) {
    Node nd;
    nd.begin = std::uint32_t(begin);
    nd.end = std::uint32_t(end);
    float lo[3] = {HUGE_VALF, HUGE_VALF, HUGE_VALF}, hi[3] = {-HUGE_VALF, -HUGE_VALF, -HUGE_VALF};
    std::uint32_t min_id = std::numeric_limits<std::uint32_t>::max(), max_id = 0;
    for (std::size_t t = begin; t < end; ++t) {
        const BuildPoint& q = pts[t];
        for (int d = 0; d < 3; ++d) {
            lo[d] = std::min(lo[d], q.c[d]);
            hi[d] = std::max(hi[d], q.c[d]);
        }
        min_id = std::min(min_id, q.id);
        max_id = std::max(max_id, q.id);
    }
    for (int d = 0; d < 3; ++d) {
        nd.lo[d] = double(lo[d]);
        nd.hi[d] = double(hi[d]);
    }
    nd.min_id = min_id;
    nd.max_id = max_id;
    if (end - begin > kBucket) {
        int axis = 0;
        for (int d = 1; d < 3; ++d)
            if (nd.hi[d] - nd.lo[d] > nd.hi[axis] - nd.lo[axis]) axis = d;
        const std::size_t mid = begin + left_size(end - begin);
        split(pts, begin, mid, end, axis);
        const std::size_t left = self + 1, right = self + 1 + subtree_nodes(mid - begin);
        nd.left = std::int32_t(left);
        nd.right = std::int32_t(right);
        if (end - begin >= kTaskMin) {
#pragma omp task default(shared) firstprivate(begin, mid, left)
            build(pts, begin, mid, left);
            build(pts, mid, end, right);
#pragma omp taskwait
        } else {
            build(pts, begin, mid, left);
            build(pts, mid, end, right);
        }
    }
    nodes_[self] = nd;
}

void AllKnnTree::all_knn_leaf(std::size_t l, std::size_t k, std::uint32_t* out) const {
    if (k > kMaxK) throw std::invalid_argument("AllKnnTree: k above " + std::to_string(kMaxK));
    k = std::min(k, n_ - 1);
    if (k == 0) return;
    const Node& own = nodes_[leaves_[l]];
    const std::size_t m = own.end - own.begin;
    Batch b;
    b.k = k;
    for (std::size_t q = 0; q < kB; ++q) {
        const bool real = q < m;
        constexpr double nan = std::numeric_limits<double>::quiet_NaN();
        b.qx[q] = real ? x_[own.begin + q] : nan;
        b.qy[q] = real ? y_[own.begin + q] : nan;
        b.qz[q] = real ? z_[own.begin + q] : nan;
        b.qi[q] = real ? id_[own.begin + q] : std::numeric_limits<std::uint32_t>::max();
        b.worst[q] = real ? HUGE_VAL : -HUGE_VAL;
        b.count[q] = 0;
    }
    scan_leaf(b, x_.data(), y_.data(), z_.data(), id_.data(), own.begin, own.end);
    // Depth first, the nearer child first; at equal box distances the child holding the leaf
    // itself, else the one nearer in input index (ties go to the nearer index, so on many equal
    // points this walks to the leaf's index neighbours first and prunes the rest: the left child
    // first would scan every leaf on the way, n^2 work). The order changes no result, only the
    // work.
    auto index_gap = [&](const Node& v) -> std::uint32_t {
        if (v.max_id < own.min_id) return own.min_id - v.max_id;
        if (v.min_id > own.max_id) return v.min_id - own.max_id;
        return 0u;
    };
    auto holds_own = [&](const Node& v) { return v.begin <= own.begin && own.begin < v.end; };
    // The nearer child is tested once, right before it is visited; the farther one waits on the
    // stack and is tested when it comes off it (with the k-th distances found meanwhile).
    std::uint32_t stack[128];
    std::size_t top = 0;
    std::int64_t cur = reaches(b, nodes_[0]) ? 0 : -1;
    for (;;) {
        if (cur < 0) {
            if (top == 0) break;
            cur = std::int64_t(stack[--top]);
            if (!reaches(b, nodes_[std::size_t(cur)])) {
                cur = -1;
                continue;
            }
        }
        const Node& v = nodes_[std::size_t(cur)];
        if (v.left < 0) {
            if (&v != &own) scan_leaf(b, x_.data(), y_.data(), z_.data(), id_.data(), v.begin, v.end);
            cur = -1;
            continue;
        }
        const Node& na = nodes_[std::size_t(v.left)];
        const Node& nb = nodes_[std::size_t(v.right)];
        const double da = box_box_d2(na, own), db = box_box_d2(nb, own);
        bool left_first = da < db;
        if (da == db) left_first = holds_own(na) || (!holds_own(nb) && index_gap(na) <= index_gap(nb));
        const std::int32_t near = left_first ? v.left : v.right, far = left_first ? v.right : v.left;
        stack[top++] = std::uint32_t(far);
        cur = reaches(b, nodes_[std::size_t(near)]) ? near : -1;
    }
    for (std::size_t q = 0; q < m; ++q)
        for (std::size_t t = 0; t < k; ++t) out[std::size_t(b.qi[q]) * k + t] = std::uint32_t(b.best[q][t]);
}

}  // namespace avsplat::detail
