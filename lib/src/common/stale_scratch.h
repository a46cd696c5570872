// Private: scratch files and folders (AtomicFile's temporary files, FusionStream's spill folders)
// carry the PID of the process that made them and hold an exclusive flock while it lives, so that
// a later run removes what a killed process (SIGKILL, a power cut) left behind.
#pragma once

#include <string>

namespace avsplat::detail {

/// Removes the entries of `folder` named `prefix` + PID + "-" + six characters whose process is
/// gone and whose lock (flock on the file, or on "<entry>/.lock" for `folders`) is free. Never
/// throws; what cannot be examined or removed is left.
void remove_stale_scratch(const std::string& folder, const std::string& prefix, bool folders);

/// Takes the exclusive flock that marks a scratch file (or a folder's lock file) as owned.
/// Returns 0, or -1 when the file system does not lock.
int lock_scratch(int fd);

}  // namespace avsplat::detail
