#include "avsplat/core/gaussians.h"
#include "common/cpu_dispatch.h"
#include "common/finite_scan.h"
#include "common/parallel.h"
#include "core/gaussian_validity.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace avsplat {

namespace {

std::string field_error(const char* field, std::size_t index, const std::string& what) {
    std::ostringstream os;
    os << "GaussianCloud." << field << "[" << index << "]: " << what;
    return os.str();
}

void check_size(const char* field, std::size_t actual, std::size_t expected, const char* shape) {
    if (actual != expected) {
        std::ostringstream os;
        os << "GaussianCloud." << field << ": expected " << expected << " floats (" << shape
           << "), got " << actual;
        throw std::invalid_argument(os.str());
    }
}

void check_shapes(const GaussianCloud& c) {
    if (c.sh_degree < 0 || c.sh_degree > kMaxShDegree) {
        throw std::invalid_argument("GaussianCloud.sh_degree: " + std::to_string(c.sh_degree) +
                                    " is not a supported SH degree (0..3)");
    }
    const std::size_t n = c.size();
    check_size("means", c.means.size(), 3 * n, "N x 3");
    check_size("scales", c.scales.size(), 3 * n, "N x 3");
    check_size("rotations", c.rotations.size(), 4 * n, "N x 4");
    check_size("sh", c.sh.size(), n * c.sh_coeffs() * 3, "N x (d+1)^2 x 3");
    if (!c.confidence.empty()) check_size("confidence", c.confidence.size(), n, "N");
    for (const auto& e : c.extras) {
        if (e.values.size() != n) {
            throw std::invalid_argument("GaussianCloud.extras['" + e.name + "']: expected " +
                                        std::to_string(n) + " values, got " +
                                        std::to_string(e.values.size()));
        }
    }
}

const char* reason_text(GaussianDefect r) {
    switch (r) {
        case GaussianDefect::NonFinite: return "NaN or Inf";
        case GaussianDefect::NegativeScale: return "negative scale";
        case GaussianDefect::ZeroRotation: return "zero-norm quaternion";
        case GaussianDefect::OpacityRange: return "opacity outside [0, 1]";
        default: return "valid";
    }
}

template <class T>
void gather(const std::vector<T>& src, std::vector<T>& dst, const std::vector<std::size_t>& idx,
            std::size_t width) {
    dst.resize(idx.size() * width);
    // In parallel from kParallelMin rows: a copy of the cloud's 19 MB (80k rows of degree 3) on
    // one thread was 2 % of simplify's time (a pure copy: the result is the same on any count).
    const std::int64_t rows = std::int64_t(idx.size());
#pragma omp parallel for schedule(static) num_threads(threads_for(idx.size()))
    for (std::int64_t j = 0; j < rows; ++j)
        std::copy_n(src.begin() + std::ptrdiff_t(idx[std::size_t(j)] * width), width,
                    dst.begin() + std::ptrdiff_t(std::size_t(j) * width));
}

}  // namespace

int sh_degree_for_coeffs(int k) {
    for (int d = 0; d <= kMaxShDegree; ++d)
        if (sh_coeffs_for_degree(d) == k) return d;
    return -1;
}

GaussianCloud::GaussianCloud(std::size_t n, int degree) {
    if (degree < 0 || degree > kMaxShDegree)
        throw std::invalid_argument("GaussianCloud: sh_degree " + std::to_string(degree) +
                                    " is not supported (0..3)");
    sh_degree = degree;
    means.assign(3 * n, 0.f);
    scales.assign(3 * n, 1.f);
    rotations.assign(4 * n, 0.f);
    for (std::size_t i = 0; i < n; ++i) rotations[4 * i] = 1.f;
    opacities.assign(n, 1.f);
    sh.assign(n * sh_coeffs() * 3, 0.f);
}

GaussianCloud GaussianCloud::from_arrays(std::size_t n, int degree, const float* m,
                                         const float* s, const float* r, const float* o,
                                         const float* c, const float* conf) {
    GaussianCloud g(n, degree);
    if (n == 0) return g;
    if (!m || !s || !r || !o || !c)
        throw std::invalid_argument("GaussianCloud::from_arrays: null array for a required field");
    std::copy_n(m, 3 * n, g.means.begin());
    std::copy_n(s, 3 * n, g.scales.begin());
    std::copy_n(r, 4 * n, g.rotations.begin());
    std::copy_n(o, n, g.opacities.begin());
    std::copy_n(c, g.sh.size(), g.sh.begin());
    if (conf) g.confidence.assign(conf, conf + n);
    return g;
}

Eigen::Matrix3d GaussianCloud::covariance(std::size_t i) const {
    if (i >= size())
        throw std::out_of_range("GaussianCloud::covariance: index " + std::to_string(i) +
                                " >= size " + std::to_string(size()));
    const float* q = &rotations[4 * i];
    Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (quat.norm() == 0.0)
        throw std::invalid_argument(field_error("rotations", i, "zero-norm quaternion"));
    quat.normalize();
    const Eigen::Matrix3d R = quat.toRotationMatrix();
    const Eigen::Vector3d s = scale(i).cast<double>();
    const Eigen::Matrix3d M = R * s.asDiagonal();
    return M * M.transpose();
}

std::pair<Eigen::Vector3f, Eigen::Vector3f> GaussianCloud::bounding_box() const {
    if (empty()) throw std::invalid_argument("GaussianCloud::bounding_box: the cloud is empty");
    Eigen::Vector3f lo = mean(0), hi = mean(0);
    for (std::size_t i = 1; i < size(); ++i) {
        lo = lo.cwiseMin(mean(i));
        hi = hi.cwiseMax(mean(i));
    }
    return {lo, hi};
}

const NamedChannel* GaussianCloud::find_extra(const std::string& name) const {
    for (const auto& e : extras)
        if (e.name == name) return &e;
    return nullptr;
}

void GaussianCloud::set_extra(const std::string& name, std::vector<float> values) {
    if (values.size() != size())
        throw std::invalid_argument("GaussianCloud::set_extra('" + name + "'): expected " +
                                    std::to_string(size()) + " values, got " +
                                    std::to_string(values.size()));
    for (auto& e : extras) {
        if (e.name == name) {
            std::copy(values.begin(), values.end(), e.values.begin());  // views of it stay valid
            return;
        }
    }
    extras.push_back({name, std::move(values)});
}

namespace {

using detail::any_non_finite;

/// Whether Gaussians [b, e) all pass check_gaussian (gaussian_validity.h): the same rule as
/// whole-array passes that vectorise (finite values; scales >= 0, no all-zero quaternion,
/// opacity in [0, 1] among finite values). Only says whether; validate finds the first defect
/// with check_gaussian itself when this says no.
AVSPLAT_CLONES_V3 bool all_valid(const GaussianCloud& c, std::size_t b, std::size_t e) {
    const std::size_t k = std::size_t(c.sh_coeffs()) * 3, m = e - b;
    if (any_non_finite(&c.means[3 * b], 3 * m) || any_non_finite(&c.scales[3 * b], 3 * m) ||
        any_non_finite(&c.rotations[4 * b], 4 * m) || any_non_finite(&c.opacities[b], m) ||
        any_non_finite(c.sh.data() + k * b, k * m))
        return false;
    if (c.has_confidence() && any_non_finite(&c.confidence[b], m)) return false;
    for (const auto& x : c.extras)
        if (any_non_finite(&x.values[b], m)) return false;
    std::uint32_t bad = 0;
    for (std::size_t j = 3 * b; j < 3 * e; ++j) bad |= std::uint32_t(c.scales[j] < 0.f);
    for (std::size_t i = b; i < e; ++i) {
        const float* q = &c.rotations[4 * i];
        bad |= std::uint32_t(q[0] == 0.f) & std::uint32_t(q[1] == 0.f) & std::uint32_t(q[2] == 0.f) &
               std::uint32_t(q[3] == 0.f);
        bad |= std::uint32_t(c.opacities[i] < 0.f) | std::uint32_t(c.opacities[i] > 1.f);
    }
    return bad == 0;
}

}  // namespace

void validate(const GaussianCloud& cloud) {
    check_shapes(cloud);
    // Valid clouds (the common case) in bulk passes; a cloud with a defect is then scanned
    // Gaussian by Gaussian for the first one.
    const std::size_t n_all = cloud.size();
    constexpr std::size_t kChunk = 4096;
    const std::int64_t chunks = std::int64_t((n_all + kChunk - 1) / kChunk);
    int any_bad = 0;
#pragma omp parallel for schedule(static) reduction(| : any_bad) num_threads(threads_for(n_all))
    for (std::int64_t ci = 0; ci < chunks; ++ci) {
        const std::size_t b = std::size_t(ci) * kChunk, e = std::min(n_all, b + kChunk);
        if (!all_valid(cloud, b, e)) any_bad = 1;
    }
    if (!any_bad) return;
    // The first bad Gaussian, found in parallel: each thread stops at the first defect of its
    // range and the smallest index wins, so the error is the serial scan's for any thread count.
    const std::size_t n = cloud.size();
    std::size_t first = n;
#pragma omp parallel for schedule(static) reduction(min : first) num_threads(threads_for(n))
    for (std::int64_t si = 0; si < std::int64_t(n); ++si) {
        const std::size_t i = std::size_t(si);
        if (i >= first) continue;
        GaussianField field = GaussianField::Means;
        if (check_gaussian(cloud, i, field) != GaussianDefect::None) first = i;
    }
    // Serially from there: the same index, field and reason as a serial scan (also when another
    // thread changed the values meanwhile: then whatever the scan sees now).
    for (std::size_t i = first; i < n; ++i) {
        GaussianField field = GaussianField::Means;
        const GaussianDefect r = check_gaussian(cloud, i, field);
        if (r != GaussianDefect::None) throw std::invalid_argument(field_error(gaussian_field_name(field), i, reason_text(r)));
    }
}

std::string SanitizeReport::summary() const {
    std::ostringstream os;
    os << "kept " << kept << ", dropped " << dropped;
    if (dropped) {
        os << " (";
        const char* sep = "";
        auto item = [&](const char* name, std::size_t v) {
            if (v) { os << sep << name << " " << v; sep = ", "; }
        };
        item("non_finite", non_finite);
        item("negative_scale", negative_scale);
        item("zero_rotation", zero_rotation);
        item("opacity_range", opacity_range);
        os << ")";
    }
    return os.str();
}

SanitizeReport sanitize(GaussianCloud& cloud) {
    check_shapes(cloud);
    SanitizeReport rep;
    std::vector<std::size_t> keep;
    keep.reserve(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
        GaussianField field = GaussianField::Means;
        switch (check_gaussian(cloud, i, field)) {
            case GaussianDefect::None: keep.push_back(i); break;
            case GaussianDefect::NonFinite: ++rep.non_finite; break;
            case GaussianDefect::NegativeScale: ++rep.negative_scale; break;
            case GaussianDefect::ZeroRotation: ++rep.zero_rotation; break;
            case GaussianDefect::OpacityRange: ++rep.opacity_range; break;
        }
    }
    rep.kept = keep.size();
    rep.dropped = cloud.size() - keep.size();
    if (!rep.dropped) return rep;
    // Compact in place, never reallocating: views of the arrays (numpy arrays in Python, or a
    // call on another thread) keep pointing at live memory. keep is increasing, so moving row
    // keep[j] down to row j never overwrites a row still to be moved.
    auto compact = [&keep](std::vector<float>& v, std::size_t width) {
        for (std::size_t j = 0; j < keep.size(); ++j)
            if (keep[j] != j) std::copy_n(v.begin() + keep[j] * width, width, v.begin() + j * width);
        v.resize(keep.size() * width);
    };
    compact(cloud.means, 3);
    compact(cloud.scales, 3);
    compact(cloud.rotations, 4);
    compact(cloud.opacities, 1);
    compact(cloud.sh, static_cast<std::size_t>(cloud.sh_coeffs()) * 3);
    if (cloud.has_confidence()) compact(cloud.confidence, 1);
    for (auto& e : cloud.extras) compact(e.values, 1);
    return rep;
}

GaussianCloud select(const GaussianCloud& c, const std::vector<std::size_t>& idx) {
    check_shapes(c);
    for (std::size_t j = 0; j < idx.size(); ++j) {
        if (idx[j] >= c.size())
            throw std::out_of_range("select: indices[" + std::to_string(j) + "] = " +
                                    std::to_string(idx[j]) + " >= size " +
                                    std::to_string(c.size()));
    }
    GaussianCloud out;
    out.sh_degree = c.sh_degree;
    out.antialiased = c.antialiased;
    gather(c.means, out.means, idx, 3);
    gather(c.scales, out.scales, idx, 3);
    gather(c.rotations, out.rotations, idx, 4);
    gather(c.opacities, out.opacities, idx, 1);
    gather(c.sh, out.sh, idx, static_cast<std::size_t>(c.sh_coeffs()) * 3);
    if (c.has_confidence()) gather(c.confidence, out.confidence, idx, 1);
    for (const auto& e : c.extras) {
        NamedChannel ch{e.name, {}};
        gather(e.values, ch.values, idx, 1);
        out.extras.push_back(std::move(ch));
    }
    return out;
}

GaussianCloud select_mask(const GaussianCloud& c, const std::vector<std::uint8_t>& mask) {
    if (mask.size() != c.size())
        throw std::invalid_argument("select_mask: mask has " + std::to_string(mask.size()) +
                                    " entries, the cloud " + std::to_string(c.size()));
    std::vector<std::size_t> idx;
    for (std::size_t i = 0; i < mask.size(); ++i)
        if (mask[i]) idx.push_back(i);
    return select(c, idx);
}

GaussianCloud concatenate(const std::vector<GaussianCloud>& clouds) {
    GaussianCloud out;
    if (clouds.empty()) return out;
    int degree = 0;
    for (const auto& c : clouds) {
        check_shapes(c);
        degree = std::max(degree, c.sh_degree);
    }
    const GaussianCloud& first = clouds.front();
    for (std::size_t k = 1; k < clouds.size(); ++k) {
        const GaussianCloud& c = clouds[k];
        if (c.has_confidence() != first.has_confidence())
            throw std::invalid_argument("concatenate: clouds[" + std::to_string(k) + "] " +
                                        (c.has_confidence() ? "has" : "lacks") +
                                        " confidence, clouds[0] does not agree");
        bool same = c.extras.size() == first.extras.size();
        for (const auto& e : first.extras) same = same && c.find_extra(e.name);
        if (!same)
            throw std::invalid_argument("concatenate: clouds[" + std::to_string(k) +
                                        "] has other extra channels than clouds[0]");
    }
    out.sh_degree = degree;
    out.antialiased = std::all_of(clouds.begin(), clouds.end(), [](const GaussianCloud& c) { return c.antialiased; });
    const std::size_t kout = static_cast<std::size_t>(sh_coeffs_for_degree(degree)) * 3;
    for (const auto& e : first.extras) out.extras.push_back({e.name, {}});
    for (const auto& c : clouds) {
        out.means.insert(out.means.end(), c.means.begin(), c.means.end());
        out.scales.insert(out.scales.end(), c.scales.begin(), c.scales.end());
        out.rotations.insert(out.rotations.end(), c.rotations.begin(), c.rotations.end());
        out.opacities.insert(out.opacities.end(), c.opacities.begin(), c.opacities.end());
        out.confidence.insert(out.confidence.end(), c.confidence.begin(), c.confidence.end());
        const std::size_t kin = static_cast<std::size_t>(c.sh_coeffs()) * 3;
        for (std::size_t i = 0; i < c.size(); ++i) {
            const auto src = c.sh.begin() + i * kin;
            out.sh.insert(out.sh.end(), src, src + kin);
            out.sh.insert(out.sh.end(), kout - kin, 0.f);
        }
        for (auto& e : out.extras) {
            const auto& v = c.find_extra(e.name)->values;
            e.values.insert(e.values.end(), v.begin(), v.end());
        }
    }
    return out;
}

}  // namespace avsplat
