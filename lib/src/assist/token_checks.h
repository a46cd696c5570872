// Argument checks shared by the token operators (assist_selection.cpp, condition_tokens.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace avsplat::assist_detail {

/// Throws std::invalid_argument unless views >= 0, tokens_per_view >= 1 and channels >= 1 (when
/// views > 0), the product fits memory indexing, and `tokens` is non-null when it is not empty.
void check_token_shape(const float* tokens, int views, int tokens_per_view, int channels);

/// Throws std::invalid_argument "<name>[i, j, k] = nan: expected finite values" for the first
/// non-finite value (memory order) of a row-major array of `shape`. Parallel; the answer is the
/// first index whatever the thread count.
void check_finite(const float* data, const std::vector<std::int64_t>& shape, const std::string& name);

}  // namespace avsplat::assist_detail
