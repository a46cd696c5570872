#include "fusion_options.h"

#include "choice_option.h"

#include "avsplat/core/names.h"

#include <string>
#include <utility>
#include <vector>

namespace avsplat::cli {

namespace {

void add_number(CLI::App& cmd, const std::string& flag, double& value, const std::string& help) {
    cmd.add_option(flag, value, help)->capture_default_str()->group("Occupancy fusion knobs");
}

}  // namespace

const char* policy_name(FusionPolicy policy) { return name_of(policy).c_str(); }

void add_fusion_options(CLI::App& cmd, FusionParams& p) {
    add_choice(cmd, "--policy", p.policy,
               enum_names<FusionPolicy>(),
               "weights of a voxel's samples: plain mean, softmax of the confidence (AnySplat) or "
               "occupancy-guided (AVSplat)");
    add_number(cmd, "--tau0", p.tau0, "base temperature, > 0");
    add_number(cmd, "--alpha", p.alpha, "occupancy exponent, >= 0");
    add_number(cmd, "--n-ref", p.n_ref, "reference occupancy, > 0");
    add_number(cmd, "--tau-min", p.tau_min, "lower temperature clip, > 0");
    add_number(cmd, "--tau-max", p.tau_max, "upper temperature clip, >= tau-min");
    add_number(cmd, "--b-conf", p.b_conf, "weight of the mean confidence in the reliability, >= 0");
    add_number(cmd, "--b-geo", p.b_geo, "weight of the geometric consistency in the reliability, >= 0");
    add_number(cmd, "--k-rel", p.k_rel, "how much unreliability raises the temperature, >= 0");
    add_number(cmd, "--eps", p.eps, "floor in the consistency, reliability and occupancy ratio, >= 0");
    add_number(cmd, "--trim-mass", p.trim_mass, "keep this weight mass per voxel; 0 or 1: no trimming");
    add_choice(cmd, "--weights", p.weights,
               enum_names<WeightFunction>(),
               "normalisation of the tempered logits (occupancy policy)");
    add_choice(cmd, "--confidence-mapping", p.confidence_mapping,
               enum_names<ConfidenceMapping>(),
               "how the confidence is read: a logit, a probability in [0, 1], or a positive 1 + exp(x) value");
    add_choice(cmd, "--shape", p.shape, enum_names<ShapeMode>(),
               "how Gaussian shapes are fused: average of log-scales and rotations, or moment matching");
    add_choice(cmd, "--precision", p.precision,
               enum_names<Precision>(),
               "scalar of the weight computation (float64 is the reference path)");
    cmd.add_flag_callback(
        "--drop-invalid", [&p] { p.on_invalid = InvalidPolicy::Drop; },
        "drop invalid samples (NaN/Inf, bad confidence, invalid Gaussians) and count them, instead of failing");
}

}  // namespace avsplat::cli
