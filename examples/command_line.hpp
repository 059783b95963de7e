// Shared by the example programs: strict parsing of a command-line number. The whole text
// must be the number, inside [aMin, aMax]; otherwise smallvcm::Error says
// "<option>: '<text>' is not <range>".
#pragma once
#include "smallvcm.hpp"

#include <charconv>
#include <sstream>
#include <string>

template <class T>
T ParseNumber(const std::string& aOption, const std::string& aText, T aMin, T aMax, const char* aRange) {
    T value{};
    const char* begin = aText.c_str();
    const char* end = begin + aText.size();
    const auto result = std::from_chars(begin, end, value);
    if (aText.empty() || result.ec != std::errc() || result.ptr != end || !(value >= aMin && value <= aMax))
        throw smallvcm::Error(aOption + ": '" + aText + "' is not " + aRange);
    return value;
}

// The same, saying "a number in [aMin, aMax]" when the value is refused.
template <class T>
T ParseNumber(const std::string& aOption, const std::string& aText, T aMin, T aMax) {
    std::ostringstream range;
    range << "a number in [" << aMin << ", " << aMax << "]";
    return ParseNumber<T>(aOption, aText, aMin, aMax, range.str().c_str());
}
