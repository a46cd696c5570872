#include "avsplat/fusion/fusion_knobs.h"

#include "avsplat/fusion/names.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <stdexcept>

namespace avsplat {

namespace {

// The shortest %g form that reads back as `v`.
std::string shortest(double v) {
    char buf[40];
    for (int precision = 1; precision <= 17; ++precision) {
        std::snprintf(buf, sizeof buf, "%.*g", precision, v);
        if (std::strtod(buf, nullptr) == v || std::isnan(v)) break;
    }
    return buf;
}

double parse_double(const std::string& name, const std::string& text) {
    const char* begin = text.c_str();
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(begin, &end);
    if (text.empty() || end != begin + text.size())
        throw std::invalid_argument(name + ": '" + text + "' is not a number");
    return v;
}

enum class Bound { Positive, NonNegative, AtLeastTauMin, Unit };

FusionKnob number(const char* name, double FusionParams::*field, const char* doc, Bound bound) {
    FusionKnob k;
    k.name = name;
    k.kind = FusionKnob::Kind::Number;
    k.doc = doc;
    k.number = field;
    switch (bound) {
        case Bound::Positive:
            k.min = 0.0;
            k.min_exclusive = true;
            k.range = "a finite value > 0";
            break;
        case Bound::NonNegative:
            k.min = 0.0;
            k.range = "a finite value >= 0";
            break;
        case Bound::AtLeastTauMin:
            k.min_knob = "tau_min";
            k.range = "a finite value >= tau_min";
            break;
        case Bound::Unit:
            k.min = 0.0;
            k.max = 1.0;
            k.range = "a finite value in [0, 1]";
            break;
    }
    k.get = [field](const FusionParams& p) { return shortest(p.*field); };
    const std::string n = name;
    k.set = [field, n](FusionParams& p, const std::string& text) { p.*field = parse_double(n, text); };
    return k;
}

template <class E>
FusionKnob choice(const char* name, E FusionParams::*field, const char* doc) {
    FusionKnob k;
    k.name = name;
    k.kind = FusionKnob::Kind::Choice;
    k.doc = doc;
    k.range = "one of " + enum_words<E>();
    for (const auto& entry : enum_names<E>()) k.words.push_back(entry.first);
    k.get = [field](const FusionParams& p) { return name_of(p.*field); };
    const std::string n = name;
    k.set = [field, n](FusionParams& p, const std::string& text) { p.*field = parse_enum<E>(text, n); };
    return k;
}

std::vector<FusionKnob> make_table() {
    using P = FusionParams;
    std::vector<FusionKnob> t;
    t.push_back(choice("policy", &P::policy,
                       "weights of a voxel's samples: plain mean, softmax of the confidence (AnySplat) or "
                       "occupancy-guided (AVSplat; the default, as it loses at most 0.3 dB to mean at voxels of one "
                       "pixel footprint and wins 0.9-1.6 dB at two or more: docs/guides/fusion.md)"));
    t.push_back(number("tau0", &P::tau0, "base temperature", Bound::Positive));
    t.push_back(number("alpha", &P::alpha, "occupancy exponent", Bound::NonNegative));
    t.push_back(number("n_ref", &P::n_ref, "reference occupancy", Bound::Positive));
    t.push_back(number("tau_min", &P::tau_min, "lower temperature clip", Bound::Positive));
    t.push_back(number("tau_max", &P::tau_max, "upper temperature clip", Bound::AtLeastTauMin));
    t.push_back(number("b_conf", &P::b_conf, "weight of the mean confidence in the reliability",
                       Bound::NonNegative));
    t.push_back(number("b_geo", &P::b_geo, "weight of the geometric consistency in the reliability",
                       Bound::NonNegative));
    t.push_back(number("k_rel", &P::k_rel, "how much unreliability raises the temperature",
                       Bound::NonNegative));
    t.push_back(number("eps", &P::eps, "floor in the consistency, reliability and occupancy ratio",
                       Bound::NonNegative));
    t.push_back(number("trim_mass", &P::trim_mass, "keep this weight mass per voxel (0 or 1: no trimming)",
                       Bound::Unit));
    t.back().none_is_zero = true;
    t.push_back(choice("weights", &P::weights, "normalisation of the tempered logits (occupancy policy)"));
    t.push_back(choice("confidence_mapping", &P::confidence_mapping,
                       "how the confidence is read: a logit, a probability in [0, 1], or a positive "
                       "1 + exp(x) value"));
    t.push_back(choice("shape", &P::shape,
                       "how Gaussian shapes are fused: average of log-scales and rotations, or moment matching"));
    t.back().gaussian_only = true;
    t.push_back(choice("on_invalid", &P::on_invalid,
                       "invalid samples (NaN/Inf, bad confidence, invalid Gaussians): raise, or drop and count "
                       "them"));
    t.push_back(choice("precision", &P::precision,
                       "scalar of the weight maths (float64 is the reference path; sums are float64 either way)"));
    return t;
}

}  // namespace

const std::vector<FusionKnob>& fusion_knobs() {
    static const std::vector<FusionKnob> table = make_table();
    return table;
}

const FusionKnob& fusion_knob(const std::string& name) {
    for (const FusionKnob& k : fusion_knobs())
        if (k.name == name) return k;
    throw std::invalid_argument("'" + name + "' is not a fusion knob; the knobs are " + fusion_knob_names());
}

std::string fusion_knob_flag(const FusionKnob& knob) {
    std::string flag = "--" + knob.name;
    for (char& c : flag)
        if (c == '_') c = '-';
    return flag;
}

std::string fusion_knob_names(bool gaussian) {
    std::string out;
    for (const FusionKnob& k : fusion_knobs()) {
        if (k.gaussian_only && !gaussian) continue;
        out += (out.empty() ? "" : ", ") + k.name;
    }
    return out;
}

}  // namespace avsplat
