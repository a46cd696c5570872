// All quality metrics: image metrics (PSNR, SSIM) and geometry metrics (chamfer, accuracy /
// completeness, point-cloud distance, statistical outlier removal).
#pragma once

#include "avsplat/metrics/geometry_metrics.h"
#include "avsplat/metrics/image_metrics.h"
