#include "fusion_options.h"

#include "avsplat/core/names.h"
#include "avsplat/fusion/fusion_knobs.h"
#include "avsplat/fusion/names.h"

#include <unistd.h>

#include <cmath>
#include <stdexcept>
#include <string>

namespace avsplat::cli {

namespace {

constexpr const char* kGroup = "Fusion knobs";

std::string join(const std::vector<std::string>& words, const char* separator) {
    std::string out;
    for (const std::string& w : words) out += (out.empty() ? "" : separator) + w;
    return out;
}

}  // namespace

const char* policy_name(FusionPolicy policy) { return name_of(policy).c_str(); }

void add_fusion_options(CLI::App& cmd, FusionParams& p) {
    for (const FusionKnob& knob : fusion_knobs()) {
        const std::string flag = fusion_knob_flag(knob);
        if (knob.kind == FusionKnob::Kind::Number) {
            cmd.add_option(flag, p.*knob.number, knob.doc + "; " + knob.range)->capture_default_str()->group(kGroup);
            continue;
        }
        const std::string words = join(knob.words, "|");
        CLI::Option* option = cmd.add_option_function<std::string>(
            flag, [&p, &knob](const std::string& word) { knob.set(p, word); }, knob.doc);
        // A word in any case becomes the table's spelling; any other word is a parse error that
        // lists the valid ones.
        option->transform(CLI::Validator(
                              [&knob, words](std::string& word) {
                                  for (const std::string& w : knob.words)
                                      if (CLI::detail::to_lower(word) == w) {
                                          word = w;
                                          return std::string();
                                      }
                                  return "'" + word + "' is not one of " + words;
                              },
                              ""))
            ->type_name(words)
            ->default_str(knob.get(p));
        if (knob.name != "policy") option->group(kGroup);
    }
    cmd.add_flag_callback(
        "--drop-invalid", [&p] { p.on_invalid = InvalidPolicy::Drop; }, "the same as --on-invalid drop");
}

// --memory-limit: bytes with an optional K, M, G or T suffix (powers of 1024); "" gives a quarter
// of the machine's physical memory.
std::size_t parse_memory_limit(const std::string& text) {
    if (text.empty()) {
        const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
        return pages > 0 && page > 0 ? std::size_t(pages) * std::size_t(page) / 4 : std::size_t(1) << 30;
    }
    std::size_t used = 0;
    double v = 0;
    try {
        v = std::stod(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    double scale = 1;
    const std::string suffix = text.substr(used);
    if (suffix == "K" || suffix == "k") scale = 1024.0;
    else if (suffix == "M") scale = 1024.0 * 1024;
    else if (suffix == "G") scale = 1024.0 * 1024 * 1024;
    else if (suffix == "T") scale = 1024.0 * 1024 * 1024 * 1024;
    else if (!suffix.empty()) used = 0;
    if (used == 0 || !(v * scale >= 1) || !std::isfinite(v))
        throw std::invalid_argument("--memory-limit: expected bytes > 0 with an optional K, M, G or T suffix, got '" +
                                    text + "'");
    // 2^64 and beyond would wrap to a small or zero limit.
    if (!(v * scale < 18446744073709551616.0))
        throw std::invalid_argument("--memory-limit: '" + text +
                                    "' is more bytes than this machine can address (2^64)");
    return std::size_t(v * scale);
}

}  // namespace avsplat::cli
