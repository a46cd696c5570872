#include "fusion/checks.h"

#include "core/invalid_samples.h"
#include "fusion/voxel_weights.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace avsplat {

void validate(const FusionParams& p) {
    const auto fail = [](const char* field, double v, const char* want) {
        std::ostringstream os;
        os << "FusionParams." << field << ": " << v << " is invalid; expected " << want;
        throw std::invalid_argument(os.str());
    };
    const auto finite = [](double v) { return std::isfinite(v); };
    if (!(finite(p.tau0) && p.tau0 > 0)) fail("tau0", p.tau0, "a finite value > 0");
    if (!(finite(p.alpha) && p.alpha >= 0)) fail("alpha", p.alpha, "a finite value >= 0");
    if (!(finite(p.n_ref) && p.n_ref > 0)) fail("n_ref", p.n_ref, "a finite value > 0");
    if (!(finite(p.tau_min) && p.tau_min > 0)) fail("tau_min", p.tau_min, "a finite value > 0");
    if (!(finite(p.tau_max) && p.tau_max >= p.tau_min)) fail("tau_max", p.tau_max, "a finite value >= tau_min");
    if (!(finite(p.b_conf) && p.b_conf >= 0)) fail("b_conf", p.b_conf, "a finite value >= 0");
    if (!(finite(p.b_geo) && p.b_geo >= 0)) fail("b_geo", p.b_geo, "a finite value >= 0");
    if (!(finite(p.k_rel) && p.k_rel >= 0)) fail("k_rel", p.k_rel, "a finite value >= 0");
    if (!(finite(p.eps) && p.eps >= 0)) fail("eps", p.eps, "a finite value >= 0");
    if (!(p.b_conf + p.b_geo + p.eps > 0)) fail("b_conf", p.b_conf, "b_conf + b_geo + eps > 0");
    if (!(p.trim_mass >= 0 && p.trim_mass <= 1)) fail("trim_mass", p.trim_mass, "a value in [0, 1] (0: off)");
    const auto enum_ok = [](auto e, int count) { return int(e) >= 0 && int(e) < count; };
    if (!enum_ok(p.policy, 3)) fail("policy", double(int(p.policy)), "Mean, Softmax or Occupancy");
    if (!enum_ok(p.weights, 2)) fail("weights", double(int(p.weights)), "Softmax or Sparsemax");
    if (!enum_ok(p.confidence_mapping, 3))
        fail("confidence_mapping", double(int(p.confidence_mapping)), "Logit, Probability or Positive");
    if (!enum_ok(p.shape, 2)) fail("shape", double(int(p.shape)), "Average or Moment");
    if (!enum_ok(p.on_invalid, 2)) fail("on_invalid", double(int(p.on_invalid)), "Raise or Drop");
    if (!enum_ok(p.precision, 2)) fail("precision", double(int(p.precision)), "Float32 or Float64");
}

namespace fusion_detail {

namespace {

const char* mapping_name(ConfidenceMapping m) {
    switch (m) {
        case ConfidenceMapping::Probability: return "probability";
        case ConfidenceMapping::Positive: return "positive";
        default: return "logit";
    }
}

std::string confidence_error(const char* field, std::size_t i, float c, ConfidenceMapping m) {
    std::string what;
    if (!std::isfinite(c)) what = "NaN or Inf";
    else if (m == ConfidenceMapping::Probability) what = "outside [0, 1]";
    else what = "negative";
    return std::string(field) + "[" + std::to_string(i) + "] = " + format_float(c) + ": " + what +
           " (confidence_mapping " + mapping_name(m) + "; pass on_invalid=drop to drop such samples)";
}

}  // namespace

std::string format_float(float v) {
    std::ostringstream os;
    os.precision(9);
    os << v;
    return os.str();
}

bool check_confidence(const float* conf, std::size_t n, const FusionParams& p, const char* field,
                      std::vector<std::uint8_t>& keep) {
    if (!conf) return false;
    const auto bad = [&](std::size_t i) { return !fusion_weights::confidence_valid(conf[i], p.confidence_mapping); };
    return apply_invalid_policy(n, bad, p.on_invalid, keep, [&](std::size_t first) {
        throw std::invalid_argument(confidence_error(field, first, conf[first], p.confidence_mapping));
    });
}


std::string feature_error(std::size_t i, std::size_t c, float v) {
    return "features[" + std::to_string(i) + ", " + std::to_string(c) + "] = " + format_float(v) +
           ": NaN or Inf (pass on_invalid=drop to drop such samples)";
}

void check_cloud_shapes(const GaussianCloud& c) {
    if (c.sh_degree < 0 || c.sh_degree > kMaxShDegree)
        throw std::invalid_argument("GaussianCloud.sh_degree: " + std::to_string(c.sh_degree) +
                                    " is not a supported SH degree (0..3)");
    const std::size_t n = c.size();
    const auto check = [](const char* field, std::size_t got, std::size_t want) {
        if (got != want)
            throw std::invalid_argument(std::string("GaussianCloud.") + field + ": expected " +
                                        std::to_string(want) + " floats, got " + std::to_string(got));
    };
    check("means", c.means.size(), 3 * n);
    check("scales", c.scales.size(), 3 * n);
    check("rotations", c.rotations.size(), 4 * n);
    check("sh", c.sh.size(), n * std::size_t(c.sh_coeffs()) * 3);
    if (c.has_confidence()) check("confidence", c.confidence.size(), n);
    for (const auto& e : c.extras) check(("extras['" + e.name + "']").c_str(), e.values.size(), n);
}

}  // namespace fusion_detail
}  // namespace avsplat
