// An option whose value is one of a few words mapped to an enum (--policy mean|softmax|occupancy).
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <utility>
#include <vector>

namespace avsplat::cli {

/// Adds `flag` to `cmd` as a choice among the words of `choices` (case-insensitive), shown in
/// --help as "word1|word2" with the current value of `value` as the default. Any other word is a
/// parse error that lists the valid ones.
template <class Enum>
CLI::Option* add_choice(CLI::App& cmd, const std::string& flag, Enum& value,
                        const std::vector<std::pair<std::string, Enum>>& choices, const std::string& help) {
    std::string names, current;
    for (const auto& [name, v] : choices) {
        names += (names.empty() ? "" : "|") + name;
        if (v == value) current = name;
    }
    // The word becomes the enum's number, which CLI11 then converts into `value`.
    CLI::Validator to_number(
        [choices, names](std::string& word) {
            for (const auto& [name, v] : choices)
                if (CLI::detail::to_lower(word) == name) {
                    word = std::to_string(static_cast<long long>(v));
                    return std::string();
                }
            return "'" + word + "' is not one of " + names;
        },
        "");
    return cmd.add_option(flag, value, help)->transform(to_number)->type_name(names)->default_str(current);
}

}  // namespace avsplat::cli
