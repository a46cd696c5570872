#include "fusion/checks.h"

#include "avsplat/core/names.h"
#include "avsplat/fusion/fusion_knobs.h"
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
    // The ranges and words are the knob table's (fusion_knobs.h).
    for (const FusionKnob& knob : fusion_knobs()) {
        if (knob.kind == FusionKnob::Kind::Choice) {
            bool named = true;
            try {
                knob.get(p);
            } catch (const std::invalid_argument&) {
                named = false;
            }
            if (!named)
                throw std::invalid_argument("FusionParams." + knob.name + ": a value outside the enum; expected " +
                                            knob.range);
            continue;
        }
        const double v = p.*knob.number;
        const double lo = knob.min_knob.empty() ? knob.min : p.*fusion_knob(knob.min_knob).number;
        const bool ok = std::isfinite(v) && (knob.min_exclusive ? v > lo : v >= lo) && v <= knob.max;
        if (!ok) fail(knob.name.c_str(), v, knob.range.c_str());
    }
    if (!(p.b_conf + p.b_geo + p.eps > 0)) fail("b_conf", p.b_conf, "b_conf + b_geo + eps > 0");
}

namespace fusion_detail {

namespace {

std::string confidence_error(const char* field, std::size_t i, float c, ConfidenceMapping m) {
    std::string what;
    if (!std::isfinite(c)) what = "NaN or Inf";
    else if (m == ConfidenceMapping::Probability) what = "outside [0, 1]";
    else what = "negative";
    return std::string(field) + "[" + std::to_string(i) + "] = " + format_float(c) + ": " + what +
           " (confidence_mapping " + name_of(m) + "; pass on_invalid=drop to drop such samples)";
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
