// Private: the simulator's random numbers. Hash-based (splitmix64) for textures, so that a
// colour is a function of the point alone; an mt19937_64 stream per view for prediction noise,
// with transforms written out here because std::*_distribution differ between standard
// libraries: results are bit-identical on every platform and for any thread count.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

namespace avsplat::sim {

constexpr double kPi = 3.14159265358979323846;

inline std::uint64_t splitmix64(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

inline double to_unit(std::uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

class Rng {
public:
    explicit Rng(std::uint64_t seed) : engine_(seed) {}
    double uniform() { return to_unit(engine_()); }  // [0, 1)
    double normal() {                                // Box-Muller, cosine branch
        const double u1 = 1.0 - uniform();           // (0, 1]
        const double u2 = uniform();
        return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
    }

private:
    std::mt19937_64 engine_;
};

}  // namespace avsplat::sim
