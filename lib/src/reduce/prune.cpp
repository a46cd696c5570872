// prune(): drop invalid and low-opacity Gaussians, then the ones the renders from the given
// cameras never composite (or composite below min_contribution). The rules and guarantees are
// in reduce/prune.h; the contributions come from render() (RenderOptions::gaussian_contributions).
#include "avsplat/reduce/prune.h"

#include "core/progress_report.h"

#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace avsplat {

std::string PruneResult::summary() const {
    std::ostringstream os;
    os << "kept " << kept << " of " << (kept + removed) << "; removed " << removed << " (degenerate " << degenerate
       << ", low_opacity " << low_opacity << ", invisible " << invisible << " at " << cameras
       << (cameras == 1 ? " camera)" : " cameras)");
    return os.str();
}

PruneResult prune(const GaussianCloud& cloud, const std::vector<Camera>& cameras, const PruneParams& params) {
    if (!(params.min_opacity >= 0.0f && params.min_opacity <= 1.0f))
        throw std::invalid_argument("PruneParams.min_opacity: must be in [0, 1], got " +
                                    std::to_string(params.min_opacity));
    if (params.min_contribution && !(*params.min_contribution >= 0.0f && *params.min_contribution <= 1.0f))
        throw std::invalid_argument("PruneParams.min_contribution: must be in [0, 1], got " +
                                    std::to_string(*params.min_contribution));
    RenderOptions options = params.render;
    options.backend = Backend::Cpu;
    options.gaussian_contributions = true;
    for (std::size_t k = 0; k < cameras.size(); ++k) {
        try {
            cameras[k].validate();
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument("cameras[" + std::to_string(k) + "]: " + e.what());
        }
    }

    PruneResult out;
    out.cameras = cameras.size();
    ProgressReport progress(cameras.size());  // cameras rendered
    // Degenerate: the one validity rule (sanitize drops exactly what validate rejects for its
    // values, keeps the order and throws for inconsistent array sizes).
    GaussianCloud valid = cloud;
    const SanitizeReport report = sanitize(valid);
    out.degenerate = report.dropped;

    std::vector<std::uint8_t> keep(valid.size(), 1);
    for (std::size_t i = 0; i < valid.size(); ++i) {
        if (valid.opacities[i] < params.min_opacity) {
            keep[i] = 0;
            ++out.low_opacity;
        }
    }
    if (!cameras.empty() && !valid.empty()) {
        // The largest contribution of each Gaussian over all pixels of all cameras.
        std::vector<float> best(valid.size(), 0.0f);
        RenderWorkspace workspace;  // one set of render buffers for all cameras
        for (const Camera& camera : cameras) {
            RenderResult r = render(valid, camera, options, workspace);
            for (std::size_t i = 0; i < valid.size(); ++i)
                if (r.contribution_max[i] > best[i]) best[i] = r.contribution_max[i];
            workspace.recycle(std::move(r));
            progress.advance(1);
        }
        for (std::size_t i = 0; i < valid.size(); ++i) {
            if (!keep[i]) continue;
            const bool invisible = params.min_contribution ? best[i] < *params.min_contribution : best[i] == 0.0f;
            if (invisible) {
                keep[i] = 0;
                ++out.invisible;
                if (best[i] > out.max_removed_contribution) out.max_removed_contribution = best[i];
            }
        }
    }
    progress.finish();
    out.cloud = select_mask(valid, keep);
    out.kept = out.cloud.size();
    out.removed = cloud.size() - out.kept;
    return out;
}

}  // namespace avsplat
