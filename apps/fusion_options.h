// The fusion knobs of `avsplat fuse` as command-line options, one per entry of the knob table
// (avsplat/fusion/fusion_knobs.h): --policy, --tau0, --alpha, --n-ref, ..., --on-invalid,
// --precision, and --drop-invalid for --on-invalid drop. Defaults are FusionParams' (the paper's
// values). A value that is not a number or not one of the listed words is a parse error; the
// ranges are checked by validate(FusionParams) when the command runs, so the message names the
// FusionParams field.
#pragma once

#include "avsplat/fusion/fusion.h"

#include <CLI/CLI.hpp>

namespace avsplat::cli {

/// Adds the options above to `cmd`; parsed values are written into `params`, which must outlive
/// the parse.
void add_fusion_options(CLI::App& cmd, FusionParams& params);

/// "mean", "softmax" or "occupancy".
const char* policy_name(FusionPolicy policy);

}  // namespace avsplat::cli
