// AVSPLAT_HD, the host/device qualifier, is defined at the bottom of the module graph
// (avsplat/common/hostdevice.h); this name keeps working for code that includes it from core.
#pragma once

#include "avsplat/common/hostdevice.h"
