// Private text helpers shared by the dataset readers (not a public header).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes {
namespace dataset_text {

/// Strips spaces, tabs and CR/LF at both ends.
std::string trim(const std::string& s);
/// Splits on `sep`, trimming every field.
std::vector<std::string> splitFields(const std::string& s, char sep);
/// Whole-string parses; false on trailing garbage, overflow or empty input.
bool parseInt64(const std::string& s, std::int64_t* out);
bool parseDouble(const std::string& s, double* out);
/// Whole file as a string; error names the path.
Expected<std::string> readTextFile(const std::string& path);
/// Writes (truncates) a file; error names the path.
Status writeTextFile(const std::string& path, const std::string& text);

}  // namespace dataset_text
}  // namespace hermes
