// Command-line checks whose failures follow the exit-code table (main.cpp): a missing input file
// is an input error (exit 3), not a usage error (CLI11's ExistingFile gives 2).
#pragma once

#include "avsplat/core/error.h"

#include <CLI/CLI.hpp>

#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <limits>
#include <string>

namespace avsplat::cli {

/// An input that must exist: a regular file, or also a folder when `folders` (SOG folders).
/// Throws avsplat::IOError (exit 3) naming the path; CLI11 passes it through.
inline CLI::Validator existing_input(bool folders = false) {
    return CLI::Validator(
        [folders](std::string& path) -> std::string {
            struct stat st;
            if (::stat(path.c_str(), &st) != 0)
                throw IOError(path + ": cannot open for reading: " + std::strerror(errno));
            if (S_ISDIR(st.st_mode) && !folders) throw IOError(path + ": is a directory, not a file");
            return std::string();
        },
        folders ? "PATH" : "FILE");
}

/// A whole number >= 1 (CLI11's PositiveNumber prints its range, up to DBL_MAX in full).
inline CLI::Validator at_least_one() {
    return CLI::Validator(
        [](std::string& text) -> std::string {
            std::size_t used = 0;
            long double v = 0;
            try {
                v = std::stold(text, &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (used != text.size() || !(v >= 1))
                return "expected a number >= 1, got '" + text + "'";
            return std::string();
        },
        "NUMBER >= 1");
}

}  // namespace avsplat::cli
