// Exception types thrown by avsplat.
//
// Bad input (shapes, NaN/Inf, out-of-range values) throws std::invalid_argument with a
// message that names the field and the first bad index. File problems throw avsplat::IOError
// naming the file and what is wrong. Device (CUDA) failures throw avsplat::DeviceError with the
// CUDA error string. Python maps these to ValueError, OSError and RuntimeError.
#pragma once

#include <stdexcept>
#include <string>

namespace avsplat {

/// A file could not be opened, read, parsed or written.
class IOError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// A file could not be written (a subclass of IOError, so callers that catch IOError see it too).
/// The destination is left as it was.
class OutputError : public IOError {
public:
    using IOError::IOError;
};

/// A back end (CUDA) failed or is not available in this build.
class DeviceError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

}  // namespace avsplat
