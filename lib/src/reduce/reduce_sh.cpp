// reduce_sh(): per Gaussian, the band bounds of reduce/reduce_sh.h; the cloud's degree is the
// largest of the per-Gaussian smallest degrees (or the forced one).
#include "avsplat/reduce/reduce_sh.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>

namespace avsplat {

std::string ReduceShResult::summary() const {
    std::ostringstream os;
    os.precision(3);
    os << "SH degree " << sh_degree_before << " -> " << sh_degree << ", bound " << max_error_bound << ", "
       << bytes_saved << " bytes saved; Gaussians by degree needed 0: " << gaussians_by_degree[0]
       << ", 1: " << gaussians_by_degree[1] << ", 2: " << gaussians_by_degree[2] << ", 3: "
       << gaussians_by_degree[3];
    return os.str();
}

double sh_truncation_bound(const float* sh, int sh_degree, int degree) {
    constexpr double kPi = 3.14159265358979323846;
    double worst = 0.0;
    for (int ch = 0; ch < 3; ++ch) {
        double bound = 0.0;
        for (int l = degree + 1; l <= sh_degree; ++l) {
            double sq = 0.0;
            for (int k = l * l; k < (l + 1) * (l + 1); ++k) sq += double(sh[3 * k + ch]) * double(sh[3 * k + ch]);
            bound += std::sqrt((2.0 * l + 1.0) / (4.0 * kPi)) * std::sqrt(sq);
        }
        worst = std::max(worst, bound);
    }
    return worst;
}

ReduceShResult reduce_sh(const GaussianCloud& cloud, double max_error, int degree) {
    validate(cloud);
    if (!(max_error >= 0.0) || !std::isfinite(max_error))
        throw std::invalid_argument("reduce_sh: max_error must be finite and >= 0, got " + std::to_string(max_error));
    if (degree < -1 || degree > cloud.sh_degree)
        throw std::invalid_argument("reduce_sh: degree must be in 0.." + std::to_string(cloud.sh_degree) +
                                    " (the cloud's SH degree) or -1 (choose), got " + std::to_string(degree));
    const std::size_t n = cloud.size();
    const int from = cloud.sh_degree, k_from = cloud.sh_coeffs();
    ReduceShResult out;
    out.sh_degree_before = from;
    // Per Gaussian, the smallest degree whose dropped bands stay within max_error. The bound
    // decreases with the degree and is 0 at the cloud's degree.
    std::vector<std::uint8_t> needed(n, 0);
#pragma omp parallel for schedule(static)
    for (std::int64_t i = 0; i < std::int64_t(n); ++i) {
        const float* sh = &cloud.sh[std::size_t(i) * std::size_t(k_from) * 3];
        int d = 0;
        while (d < from && sh_truncation_bound(sh, from, d) > max_error) ++d;
        needed[std::size_t(i)] = std::uint8_t(d);
    }
    int chosen = 0;
    for (const std::uint8_t d : needed) {
        ++out.gaussians_by_degree[d];
        chosen = std::max(chosen, int(d));
    }
    if (degree >= 0) chosen = degree;
    out.sh_degree = chosen;

    double bound = 0.0;
#pragma omp parallel for schedule(static) reduction(max : bound)
    for (std::int64_t i = 0; i < std::int64_t(n); ++i)
        bound = std::max(bound, sh_truncation_bound(&cloud.sh[std::size_t(i) * std::size_t(k_from) * 3], from, chosen));
    out.max_error_bound = bound;

    GaussianCloud& c = out.cloud;
    c.sh_degree = chosen;
    c.means = cloud.means;
    c.scales = cloud.scales;
    c.rotations = cloud.rotations;
    c.opacities = cloud.opacities;
    c.confidence = cloud.confidence;
    c.extras = cloud.extras;
    c.antialiased = cloud.antialiased;  // the same Gaussians: rendered with the same filter
    const std::size_t k_to = std::size_t(sh_coeffs_for_degree(chosen));
    c.sh.resize(n * k_to * 3);
    for (std::size_t i = 0; i < n; ++i)
        std::copy_n(&cloud.sh[i * std::size_t(k_from) * 3], k_to * 3, &c.sh[i * k_to * 3]);
    out.bytes_saved = n * (std::size_t(k_from) - k_to) * 3 * sizeof(float);
    return out;
}

}  // namespace avsplat
