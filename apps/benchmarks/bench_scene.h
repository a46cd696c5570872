// The synthetic scene, viewpoints and command line shared by the renderer benchmarks
// (bench_render.cpp for the CPU renderer, bench_render_cuda.cpp for CUDA beside the CPU), so
// that both measure exactly the same frames and take the same options.
//
// Scene: N Gaussians of SH degree 3 in the cube [-1, 1]^3, with random rotations, anisotropic
// scales log-uniform in [0.003, 0.03], opacities uniform in [0.05, 1] and random SH (DC
// coefficients ~ N(0, 1), higher bands ~ N(0, 0.15^2)). Views: V cameras on a circle of radius
// 3.5 at height 0.8 around the cube, looking at the origin, 50 degrees vertical field of view.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"

#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

namespace avsplat::bench {

/// The options common to the renderer benchmarks, with their defaults.
struct SceneArgs {
    std::size_t gaussians = 500000;  ///< --gaussians N
    int width = 1280;                ///< --width W, pixels
    int height = 720;                ///< --height H, pixels
    int views = 5;                   ///< --views V
    int repeats = 3;                 ///< --repeats R: runs per view, the best is kept
};

/// Parses "--gaussians N --width W --height H --views V --repeats R" (any subset, any order)
/// into `args`. Prints "unknown option X" to stderr and returns false for any other option.
inline bool parse_scene_args(int argc, char** argv, SceneArgs& args) {
    for (int a = 1; a + 1 < argc; a += 2) {
        const std::string key = argv[a];
        const long v = std::strtol(argv[a + 1], nullptr, 10);
        if (key == "--gaussians") args.gaussians = std::size_t(v);
        else if (key == "--width") args.width = int(v);
        else if (key == "--height") args.height = int(v);
        else if (key == "--views") args.views = int(v);
        else if (key == "--repeats") args.repeats = int(v);
        else {
            std::fprintf(stderr, "unknown option %s\n", key.c_str());
            return false;
        }
    }
    return true;
}

/// The benchmark scene of `n` Gaussians (see the header comment), deterministic in `seed`.
inline GaussianCloud make_scene(std::size_t n, std::uint32_t seed) {
    GaussianCloud cloud(n, 3);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f),
        log_scale(std::log(0.003f), std::log(0.03f)), opacity(0.05f, 1.0f);
    std::normal_distribution<float> gauss(0.0f, 1.0f);
    const int k = cloud.sh_coeffs();
    for (std::size_t i = 0; i < n; ++i) {
        for (int c = 0; c < 3; ++c) {
            cloud.means[3 * i + c] = unit(rng);
            cloud.scales[3 * i + c] = std::exp(log_scale(rng));
        }
        Eigen::Vector4f q(gauss(rng), gauss(rng), gauss(rng), gauss(rng));
        q.normalize();
        for (int c = 0; c < 4; ++c) cloud.rotations[4 * i + c] = q[c];
        cloud.opacities[i] = opacity(rng);
        for (int j = 0; j < k; ++j)
            for (int c = 0; c < 3; ++c)
                cloud.sh[(i * k + j) * 3 + c] = (j == 0 ? 1.0f : 0.15f) * gauss(rng);
    }
    return cloud;
}

/// `views` cameras of `width` x `height` pixels evenly spaced on the circle around the scene
/// (see the header comment), view 0 on the +x axis.
inline std::vector<Camera> make_views(int views, int width, int height) {
    std::vector<Camera> cameras;
    for (int v = 0; v < views; ++v) {
        const double angle = 2.0 * M_PI * v / views;
        const Eigen::Vector3d eye(3.5 * std::cos(angle), 0.8, 3.5 * std::sin(angle));
        cameras.push_back(Camera::look_at(eye, Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 1, 0),
                                          50.0, width, height));
    }
    return cameras;
}

}  // namespace avsplat::bench
