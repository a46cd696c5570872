// The formats a subcommand reads, for its --help, made from the I/O module's table of formats
// (io/names.h), so that no help text lists fewer formats than the readers read.
#pragma once

#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/names.h"

#include <string>

namespace avsplat::cli {

/// "3DGS PLY, compressed PLY, .splat, SPZ, SOG (detected by content)", and with `npz` true
/// "; or a prediction .npz (per-pixel Gaussians or point maps)". Formats this build cannot read
/// are left out.
inline std::string readable_formats(bool npz) {
    std::string list;
    for (const auto& [word, format] : enum_names<GaussianFormat>())
        if (can_read_gaussian_format(format)) list += (list.empty() ? "" : ", ") + std::string(gaussian_format_name(format));
    list += " (detected by content)";
    if (npz) list += "; or a prediction .npz (per-pixel Gaussians or point maps)";
    return list;
}

}  // namespace avsplat::cli
