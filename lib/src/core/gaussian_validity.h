// What makes one Gaussian valid: the single rule behind validate() and sanitize()
// (gaussians.cpp), the drop policy of fuse_gaussians, and the CUDA renderer's check of
// device-resident inputs. Header-only, AVSPLAT_HD, no STL in the device part.
//
// A Gaussian is valid when every float of its fields is finite, its scales are >= 0, its
// quaternion is not all zeros and its opacity lies in [0, 1]. The checks run in that order and
// the first failure names the defect and the field (non-finite fields in the order means,
// scales, rotations, opacities, sh, then confidence and extras when the cloud has them).
#pragma once

#include "avsplat/common/hostdevice.h"

namespace avsplat {

/// Why a Gaussian is invalid; None when it is valid. The order matches SanitizeReport.
enum class GaussianDefect : int { None = 0, NonFinite, NegativeScale, ZeroRotation, OpacityRange };

/// The field that a GaussianDefect is about.
enum class GaussianField : int { Means = 0, Scales, Rotations, Opacities, Sh, Confidence, Extras };

/// Whether x is finite (not NaN, not +-inf); the same on host and device, with no libm call.
AVSPLAT_HD bool finite_float(float x) { return x - x == 0.f; }

AVSPLAT_HD bool all_finite_floats(const float* p, int n) {
    for (int k = 0; k < n; ++k)
        if (!finite_float(p[k])) return false;
    return true;
}

/// The first non-finite field of one Gaussian among its core fields: mean[3], scale[3],
/// quat[4] (w, x, y, z), opacity and sh[sh_floats]. Returns false and sets `field` when one is
/// non-finite, else returns true.
AVSPLAT_HD bool core_fields_finite(const float* mean, const float* scale, const float* quat, float opacity,
                                   const float* sh, int sh_floats, GaussianField& field) {
    const float* arrays[5] = {mean, scale, quat, &opacity, sh};
    const int sizes[5] = {3, 3, 4, 1, sh_floats};
    for (int f = 0; f < 5; ++f) {
        if (!all_finite_floats(arrays[f], sizes[f])) {
            field = GaussianField(f);
            return false;
        }
    }
    return true;
}

/// The range checks that follow the finiteness checks: negative scale, zero quaternion,
/// opacity outside [0, 1]. Sets `field` when it returns a defect.
AVSPLAT_HD GaussianDefect shape_defect(const float* scale, const float* quat, float opacity, GaussianField& field) {
    if (scale[0] < 0.f || scale[1] < 0.f || scale[2] < 0.f) {
        field = GaussianField::Scales;
        return GaussianDefect::NegativeScale;
    }
    if (quat[0] == 0.f && quat[1] == 0.f && quat[2] == 0.f && quat[3] == 0.f) {
        field = GaussianField::Rotations;
        return GaussianDefect::ZeroRotation;
    }
    if (opacity < 0.f || opacity > 1.f) {
        field = GaussianField::Opacities;
        return GaussianDefect::OpacityRange;
    }
    return GaussianDefect::None;
}

/// The defect of a Gaussian without confidence or extra channels (the renderer's inputs):
/// core_fields_finite, then shape_defect.
AVSPLAT_HD GaussianDefect check_gaussian(const float* mean, const float* scale, const float* quat, float opacity,
                                         const float* sh, int sh_floats, GaussianField& field) {
    if (!core_fields_finite(mean, scale, quat, opacity, sh, sh_floats, field)) return GaussianDefect::NonFinite;
    return shape_defect(scale, quat, opacity, field);
}

/// Name of a field in error messages ("means", ...), as in GaussianCloud.
AVSPLAT_HD const char* gaussian_field_name(GaussianField f) {
    switch (f) {
        case GaussianField::Means: return "means";
        case GaussianField::Scales: return "scales";
        case GaussianField::Rotations: return "rotations";
        case GaussianField::Opacities: return "opacities";
        case GaussianField::Sh: return "sh";
        case GaussianField::Confidence: return "confidence";
        default: return "extras";
    }
}

}  // namespace avsplat

#if !defined(__CUDACC__)
#include "avsplat/core/gaussians.h"

namespace avsplat {

/// The defect of Gaussian i of a cloud whose arrays have their documented sizes (i < size()):
/// check_gaussian's rule, with the confidence and every extra channel also required finite.
inline GaussianDefect check_gaussian(const GaussianCloud& c, std::size_t i, GaussianField& field) {
    const int k = c.sh_coeffs() * 3;
    const float* s = &c.scales[3 * i];
    const float* q = &c.rotations[4 * i];
    if (!core_fields_finite(&c.means[3 * i], s, q, c.opacities[i], c.sh.data() + std::size_t(k) * i, k, field))
        return GaussianDefect::NonFinite;
    if (c.has_confidence() && !finite_float(c.confidence[i])) {
        field = GaussianField::Confidence;
        return GaussianDefect::NonFinite;
    }
    for (const auto& e : c.extras) {
        if (!finite_float(e.values[i])) {
            field = GaussianField::Extras;
            return GaussianDefect::NonFinite;
        }
    }
    return shape_defect(s, q, c.opacities[i], field);
}

}  // namespace avsplat
#endif
