// The knobs of FusionParams as one table: name, kind, default, valid range and a line of
// documentation each. The Python keyword arguments and their checks, the command-line flags
// and their --help, the Dask forwarding and the documentation are all made from it, so a knob
// added to FusionParams and to this table appears everywhere at once.
#pragma once

#include "avsplat/fusion/fusion.h"

#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace avsplat {

/// One field of FusionParams.
struct FusionKnob {
    enum class Kind { Number, Choice };

    /// The FusionParams field, which is also the Python keyword; the command-line flag is
    /// "--" + name with '-' for '_' (fusion_knob_flag).
    std::string name;
    Kind kind = Kind::Number;
    std::string doc;    ///< one line: what the knob does
    std::string range;  ///< the valid values in words: "a finite value > 0", "one of 'mean', ..."
    bool gaussian_only = false;  ///< applies to fuse_gaussians only (shape)
    bool none_is_zero = false;   ///< Python's None stands for 0 ("off": trim_mass)

    /// Number knobs: the field and its valid range: finite, and >= min (> min when
    /// min_exclusive; >= the knob min_knob when that is named), <= max.
    double FusionParams::*number = nullptr;
    double min = -std::numeric_limits<double>::infinity();
    bool min_exclusive = false;
    std::string min_knob;
    double max = std::numeric_limits<double>::infinity();
    /// Choice knobs: the valid words, in the enum's order (its names table, */names.h).
    std::vector<std::string> words;

    /// The knob's value in `p` as text: a number in its shortest round-trip form, or a word.
    std::function<std::string(const FusionParams& p)> get;
    /// Sets the knob in `p` from text (a number, or one of `words`). Throws std::invalid_argument
    /// "<name>: ..." for text that is not a number or not a valid word. Ranges are checked by
    /// validate(FusionParams).
    std::function<void(FusionParams& p, const std::string& text)> set;
};

/// Every knob of FusionParams, policy first, in the order --help and the docs list them.
const std::vector<FusionKnob>& fusion_knobs();

/// The knob called `name`. Throws std::invalid_argument naming every knob for an unknown name.
const FusionKnob& fusion_knob(const std::string& name);

/// "--tau-min" for the knob "tau_min".
std::string fusion_knob_flag(const FusionKnob& knob);

/// The knobs' names joined by ", " (for messages); with `gaussian` false the Gaussian-only
/// knobs are left out.
std::string fusion_knob_names(bool gaussian = true);

}  // namespace avsplat
