// The fusion knobs of `avsplat fuse` as command-line options, one per entry of the knob table
// (avsplat/fusion/fusion_knobs.h): --policy, --tau0, --alpha, --n-ref, ..., --on-invalid,
// --precision, and --drop-invalid for --on-invalid drop. Defaults are FusionParams' (the paper's
// values). A value that is not a number or not one of the listed words is a parse error; the
// ranges are checked by validate(FusionParams) when the command runs, so the message names the
// FusionParams field.
#pragma once

#include "avsplat/fusion/fusion.h"

#include <CLI/CLI.hpp>

#include <cstddef>
#include <string>

namespace avsplat::cli {

/// Adds the options above to `cmd`; parsed values are written into `params`, which must outlive
/// the parse.
void add_fusion_options(CLI::App& cmd, FusionParams& params);

/// --memory-limit: bytes with an optional K, M, G or T suffix (powers of 1024); "" gives a quarter
/// of the machine's physical memory. Throws std::invalid_argument naming the option.
std::size_t parse_memory_limit(const std::string& text);

/// "mean", "softmax" or "occupancy".
const char* policy_name(FusionPolicy policy);

}  // namespace avsplat::cli
