// Input checks of the fusion entry points: array shapes and confidence domains, with the error
// messages that name the field and the first bad index. (FusionParams are checked by the public
// validate(const FusionParams&) in fusion.h.)
#pragma once

#include "avsplat/fusion/fusion.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace avsplat::fusion_detail {

// A float with the 9 significant digits that identify it, for error messages.
std::string format_float(float v);

// Checks the confidence conf[0..n) (null: none) against p.confidence_mapping under
// p.on_invalid. Raise: throws std::invalid_argument naming field[i] at the first invalid one.
// Drop: clears keep[i] for every invalid one (keep holds n flags, allocated on first use).
// Returns whether any was invalid.
bool check_confidence(const float* conf, std::size_t n, const FusionParams& p, const char* field,
                      std::vector<std::uint8_t>& keep);

// The message for a non-finite feature at features[i, c] = v.
std::string feature_error(std::size_t i, std::size_t c, float v);

// Throws std::invalid_argument ("GaussianCloud.<field>: expected ...") when the cloud's SH degree
// is unsupported or an array's size does not match size().
void check_cloud_shapes(const GaussianCloud& c);

}  // namespace avsplat::fusion_detail
