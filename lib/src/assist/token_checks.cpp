#include "assist/token_checks.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace avsplat::assist_detail {

void check_token_shape(const float* tokens, int views, int tokens_per_view, int channels) {
    if (views < 0) throw std::invalid_argument("tokens: the number of views must be >= 0");
    if (views == 0) return;
    if (tokens_per_view < 1 || channels < 1)
        throw std::invalid_argument("tokens: expected at least one token and one channel per view, got P = " +
                                    std::to_string(tokens_per_view) + ", C = " + std::to_string(channels));
    const double n = double(views) * double(tokens_per_view) * double(channels);
    if (n > double(std::numeric_limits<std::int64_t>::max() / 8))
        throw std::invalid_argument("tokens: too many values");
    if (tokens == nullptr) throw std::invalid_argument("tokens: missing");
}

void check_finite(const float* data, const std::vector<std::int64_t>& shape, const std::string& name) {
    std::int64_t n = 1;
    for (std::int64_t d : shape) n *= d;
    if (n == 0) return;
    const std::int64_t d2 = shape.empty() ? 1 : shape.back();
    const std::int64_t rows = n / d2;
    std::int64_t first = std::numeric_limits<std::int64_t>::max();
    // Rows in parallel; the smallest bad flat index wins whatever the thread that saw it.
#pragma omp parallel for schedule(static) reduction(min : first)
    for (std::int64_t r = 0; r < rows; ++r) {
        if (r * d2 >= first) continue;
        const float* row = data + r * d2;
        for (std::int64_t c = 0; c < d2; ++c)
            if (!std::isfinite(row[c])) {
                first = std::min(first, r * d2 + c);
                break;
            }
    }
    if (first == std::numeric_limits<std::int64_t>::max()) return;
    std::ostringstream msg;
    std::vector<std::int64_t> index(shape.size());
    std::int64_t rest = first;
    for (std::size_t a = shape.size(); a-- > 0;) {
        index[a] = rest % shape[a];
        rest /= shape[a];
    }
    msg << name << "[";
    for (std::size_t a = 0; a < index.size(); ++a) msg << (a ? ", " : "") << index[a];
    msg << "] = " << data[first] << ": expected finite values";
    throw std::invalid_argument(msg.str());
}

}  // namespace avsplat::assist_detail
