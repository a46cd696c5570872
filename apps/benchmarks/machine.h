// One line that says which machine a benchmark ran on, printed beside every figure, so that
// figures from different machines are never compared as if they came from one: the CPU model
// and its x86 family/model (Zen 3 is family 25 model 1, Zen 4 family 25 model 17, Zen 5 family
// 26), whether it has AVX2 and AVX-512, the cores, the threads the benchmark uses, the kernel's
// transparent-huge-page setting and the load average (the machines are shared).
#pragma once

#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <thread>

namespace avsplat::bench {

inline std::string cpuinfo_field(const std::string& text, const std::string& key) {
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
        if (line.compare(0, key.size(), key) != 0) continue;
        const std::size_t colon = line.find(':');
        if (colon == std::string::npos) continue;
        std::string v = line.substr(colon + 1);
        v.erase(0, v.find_first_not_of(' '));
        return v;
    }
    return "?";
}

inline std::string machine_description(int threads) {
    std::ifstream cpu("/proc/cpuinfo");
    std::string text((std::istreambuf_iterator<char>(cpu)), std::istreambuf_iterator<char>());
    const std::string flags = " " + cpuinfo_field(text, "flags") + " ";
    std::string thp = "?";
    {
        std::ifstream f("/sys/kernel/mm/transparent_hugepage/enabled");  // "always [madvise] never"
        std::string line;
        if (std::getline(f, line)) {
            const std::size_t a = line.find('['), b = line.find(']');
            thp = a != std::string::npos && b > a ? line.substr(a + 1, b - a - 1) : line;
        }
    }
    double load = -1;
    {
        std::ifstream f("/proc/loadavg");
        f >> load;
    }
    char buf[96];
    std::snprintf(buf, sizeof buf, "load average %.1f", load);
    return "machine: " + cpuinfo_field(text, "model name") + " (family " + cpuinfo_field(text, "cpu family") +
           " model " + cpuinfo_field(text, "model\t") + ", AVX2 " +
           (flags.find(" avx2 ") != std::string::npos ? "yes" : "no") + ", AVX-512 " +
           (flags.find(" avx512f ") != std::string::npos ? "yes" : "no") + "), " +
           std::to_string(std::thread::hardware_concurrency()) + " cores, " + std::to_string(threads) +
           " thread" + (threads == 1 ? "" : "s") + ", transparent huge pages " + thp + ", " + buf;
}

}  // namespace avsplat::bench
