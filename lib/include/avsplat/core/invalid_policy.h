// InvalidPolicy: what the fusion entry points and the voxel grid do with an invalid sample.
#pragma once

namespace avsplat {

/// What to do with an invalid sample (NaN or Inf in a field, a confidence outside the domain
/// of its mapping, an invalid Gaussian): throw std::invalid_argument naming the field and the
/// first bad index, or drop the sample and count it.
enum class InvalidPolicy { Raise, Drop };

}  // namespace avsplat
