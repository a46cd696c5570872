#include "fusion_options.h"

#include "avsplat/core/names.h"
#include "avsplat/fusion/fusion_knobs.h"
#include "avsplat/fusion/names.h"

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

}  // namespace avsplat::cli
