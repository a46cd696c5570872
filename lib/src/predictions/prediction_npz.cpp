#include "avsplat/predictions/prediction_npz.h"

#include "avsplat/core/error.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/npz.h"
#include "avsplat/point_maps/point_maps.h"
#include "avsplat/core/sh.h"

#include <cstdint>
#include <limits>

namespace avsplat {

namespace {

std::string join_shape(const std::vector<std::size_t>& shape) {
    std::string s = "(";
    for (std::size_t k = 0; k < shape.size(); ++k) s += (k ? ", " : "") + std::to_string(shape[k]);
    return s + (shape.size() == 1 ? ",)" : ")");
}

// The leading shape L of `points` and the arrays' checks against it.
class Layout {
public:
    Layout(const std::string& path, const NpyArray& points) : path_(path) {
        const auto& s = points.shape;
        if ((s.size() != 4 && s.size() != 2) || s.back() != 3)
            throw IOError(path + ": array 'points' has shape " + points.shape_string() +
                          ", expected (S, H, W, 3) or (N, 3)");
        lead_.assign(s.begin(), s.end() - 1);
        symbols_ = lead_.size() == 3 ? "S, H, W" : "N";
        for (std::size_t d : lead_) {
            if (d > static_cast<std::size_t>(std::numeric_limits<int>::max()))
                throw IOError(path + ": array 'points' has shape " + points.shape_string() + ", too large");
            pixels_ *= d;
        }
        views_ = lead_.size() == 3 ? static_cast<int>(lead_[0]) : 1;
        height_ = lead_.size() == 3 ? static_cast<int>(lead_[1]) : 1;
        width_ = lead_.size() == 3 ? static_cast<int>(lead_[2]) : static_cast<int>(lead_[0]);
    }

    std::size_t pixels() const { return pixels_; }
    int views() const { return views_; }
    int height() const { return height_; }
    int width() const { return width_; }
    std::string dims() const {
        return lead_.size() == 3 ? std::to_string(views_) + " x " + std::to_string(height_) + " x " + std::to_string(width_)
                                 : std::to_string(width_) + " points";
    }

    // The array's values as float32 after checking that its shape is L + tail; tail entries
    // of 0 match any size (the channel count C of features).
    std::vector<float> take(const NpyArray& a, const std::vector<std::size_t>& tail, const char* tail_symbols) const {
        check(a, tail, tail_symbols);
        return a.to_float32();
    }

    void check(const NpyArray& a, const std::vector<std::size_t>& tail, const char* tail_symbols) const {
        bool ok = a.shape.size() == lead_.size() + tail.size();
        for (std::size_t k = 0; ok && k < a.shape.size(); ++k) {
            const std::size_t want = k < lead_.size() ? lead_[k] : tail[k - lead_.size()];
            ok = want == 0 || a.shape[k] == want;
        }
        if (!ok) {
            std::vector<std::size_t> expected = lead_;
            expected.insert(expected.end(), tail.begin(), tail.end());
            std::string sym = symbols_;
            if (*tail_symbols) sym += std::string(", ") + tail_symbols;
            throw IOError(path_ + ": array '" + a.name + "' has shape " + a.shape_string() + ", expected (" + sym +
                          ") with " + symbols_ + " = " + join_shape(lead_) + " of 'points'");
        }
    }

private:
    std::string path_;
    std::vector<std::size_t> lead_;
    std::string symbols_;
    std::size_t pixels_ = 1;
    int views_ = 1, height_ = 1, width_ = 1;
};

// The shapes of the arrays read_prediction_npz uses, checked from the .npy headers before any
// array is inflated: a wrong shape costs nothing, whatever size it declares.
void check_shapes(const std::string& path, const std::vector<NpyArray>& headers) {
    const NpyArray* points = find_array(headers, "points");
    if (!points) return;  // reported after reading, with the expected layouts
    const Layout L(path, *points);
    for (const NpyArray& a : headers) {
        if (a.name == "valid" || a.name == "confidence" || a.name == "opacities") L.check(a, {}, "");
        else if (a.name == "colors" || a.name == "scales" || a.name == "normals") L.check(a, {3}, "3");
        else if (a.name == "rotations") L.check(a, {4}, "4");
        else if (a.name == "features") L.check(a, {0}, "C");
        else if (a.name == "sh" && a.shape.size() == points->shape.size() + 1) L.check(a, {0, 3}, "K, 3");
        else if (a.name == "sh") L.check(a, {3}, "3");
    }
}

}  // namespace

PredictionSamples read_prediction_npz(const std::string& path, const std::vector<Camera>& cameras) {
    const std::vector<NpyArray> arrays =
        read_npz(path, [&](const std::vector<NpyArray>& headers) { check_shapes(path, headers); });
    auto get = [&](const char* name) { return find_array(arrays, name); };
    const NpyArray* points_a = get("points");
    if (!points_a) throw IOError(path + ": no array 'points' (expected a prediction .npz with points (S, H, W, 3))");
    const Layout L(path, *points_a);
    const std::size_t n = L.pixels();

    const std::vector<float> points = L.take(*points_a, {3}, "3");
    std::vector<std::uint8_t> valid(n, 1);
    if (const NpyArray* a = get("valid")) {
        const std::vector<float> v = L.take(*a, {}, "");
        for (std::size_t i = 0; i < n; ++i) valid[i] = v[i] != 0.0f;
    }
    std::vector<std::size_t> source;  // flat pixel index of each kept sample
    source.reserve(n);
    for (std::size_t i = 0; i < n; ++i)
        if (valid[i]) source.push_back(i);
    const std::size_t m = source.size();

    std::vector<float> confidence;
    if (const NpyArray* a = get("confidence")) confidence = L.take(*a, {}, "");
    std::vector<float> colors;
    if (const NpyArray* a = get("colors")) colors = L.take(*a, {3}, "3");

    PredictionSamples out;
    const NpyArray *scales_a = get("scales"), *rotations_a = get("rotations"), *opacities_a = get("opacities");
    const NpyArray* sh_a = get("sh");
    const NpyArray* features_a = get("features");

    if (scales_a || rotations_a || opacities_a || sh_a) {
        // 1. Per-pixel Gaussians.
        for (const char* name : {"scales", "rotations", "opacities"})
            if (!get(name))
                throw IOError(path + ": has Gaussian parameters but no array '" + name +
                              "' (per-pixel Gaussians need scales, rotations, opacities and sh or colors)");
        const std::vector<float> scales = L.take(*scales_a, {3}, "3");
        const std::vector<float> rotations = L.take(*rotations_a, {4}, "4");
        const std::vector<float> opacities = L.take(*opacities_a, {}, "");
        int degree = 0;
        std::vector<float> sh;
        if (sh_a) {
            const std::size_t rank = points_a->shape.size() - 1;
            const bool banded = sh_a->shape.size() == rank + 2;  // L x K x 3, else L x 3
            const std::size_t k = banded ? sh_a->shape[rank] : 1;
            degree = k <= 16 ? sh_degree_for_coeffs(static_cast<int>(k)) : -1;
            if (degree < 0)
                throw IOError(path + ": array 'sh' has shape " + sh_a->shape_string() +
                              ": K = " + std::to_string(k) + " SH coefficients, expected 1, 4, 9 or 16");
            sh = banded ? L.take(*sh_a, {k, 3}, "K, 3") : L.take(*sh_a, {3}, "3");
        } else if (colors.empty()) {
            throw IOError(path + ": per-pixel Gaussians need an array 'sh' or 'colors' for their colour");
        }
        const int K = sh_coeffs_for_degree(degree);
        GaussianCloud& g = out.gaussians;
        g = GaussianCloud(m, degree);
        if (!confidence.empty()) g.confidence.resize(m);
        for (std::size_t j = 0; j < m; ++j) {
            const std::size_t i = source[j];
            for (int c = 0; c < 3; ++c) {
                g.means[3 * j + c] = points[3 * i + c];
                g.scales[3 * j + c] = scales[3 * i + c];
            }
            for (int c = 0; c < 4; ++c) g.rotations[4 * j + c] = rotations[4 * i + c];
            g.opacities[j] = opacities[i];
            if (sh_a) {
                for (int c = 0; c < 3 * K; ++c) g.sh[3 * K * j + c] = sh[3 * K * i + c];
            } else {
                // The same colour -> degree-0 coefficient rule as gaussians_from_point_maps.
                for (int c = 0; c < 3; ++c)
                    g.sh[3 * j + c] = static_cast<float>((colors[3 * i + c] - 0.5) / sh::kC0);
            }
            if (!confidence.empty()) g.confidence[j] = confidence[i];
        }
        out.kind = PredictionSamples::Kind::Gaussians;
        out.description = "per-pixel Gaussians (" + L.dims() + ", SH degree " + std::to_string(degree) + ")";
        if (features_a) out.description += "; 'features' ignored";
        return out;
    }

    if (features_a) {
        // 2. Raw features.
        const std::vector<float> features = L.take(*features_a, {0}, "C");
        const std::size_t C = features_a->shape.back();
        if (C > static_cast<std::size_t>(std::numeric_limits<int>::max()))
            throw IOError(path + ": array 'features' has too many channels (" + std::to_string(C) + ")");
        out.kind = PredictionSamples::Kind::Features;
        out.channels = static_cast<int>(C);
        out.positions.resize(3 * m);
        out.features.resize(C * m);
        if (!confidence.empty()) out.confidence.resize(m);
        for (std::size_t j = 0; j < m; ++j) {
            const std::size_t i = source[j];
            for (int c = 0; c < 3; ++c) out.positions[3 * j + c] = points[3 * i + c];
            for (std::size_t c = 0; c < C; ++c) out.features[C * j + c] = features[C * i + c];
            if (!confidence.empty()) out.confidence[j] = confidence[i];
        }
        out.description = "raw features (" + L.dims() + ", C = " + std::to_string(C) + ")";
        return out;
    }

    if (colors.empty())
        throw IOError(path + ": 'points' alone is not enough: add Gaussian parameters (scales, rotations, "
                      "opacities, sh), raw 'features', or 'colors' (point maps)");
    // 3. Point maps.
    std::vector<float> normals;
    if (const NpyArray* a = get("normals")) normals = L.take(*a, {3}, "3");
    if (!cameras.empty() && static_cast<int>(cameras.size()) != L.views())
        throw IOError(path + ": " + std::to_string(cameras.size()) + " cameras given for " +
                      std::to_string(L.views()) + " views");
    PointMaps maps;
    maps.views = L.views();
    maps.height = L.height();
    maps.width = L.width();
    maps.points = points.data();
    maps.colors = colors.data();
    maps.confidence = confidence.empty() ? nullptr : confidence.data();
    maps.normals = normals.empty() ? nullptr : normals.data();
    maps.valid = valid.data();
    out.kind = PredictionSamples::Kind::Gaussians;
    out.gaussians = gaussians_from_point_maps(maps, cameras);
    out.description = "point maps (" + L.dims() + ", " +
                      (cameras.empty() ? std::string("kNN scale") : std::string("pixel-footprint scale")) + ")";
    return out;
}

GaussianCloud read_gaussian_input(const std::string& path, const std::vector<Camera>& cameras) {
    if (file_extension(path) != ".npz") return read_gaussians(path);
    PredictionSamples p = read_prediction_npz(path, cameras);
    if (p.kind != PredictionSamples::Kind::Gaussians)
        throw IOError(path + ": holds raw features, not Gaussians (fuse them with `avsplat fuse ... -o OUT.npz`)");
    return std::move(p.gaussians);
}

}  // namespace avsplat
