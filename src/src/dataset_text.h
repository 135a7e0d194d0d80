// Private text helpers shared by the dataset readers (not a public header).
#pragma once

#include <cstdint>
#include <functional>
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
/// Calls `row(text, where)` for each line of `path` holding data: trimmed, neither
/// empty nor a '#' comment; `where` is "path:line" for the row's errors. Stops at
/// the first error and returns it. `what` names the file in the error when it
/// cannot be opened ("image list", "ground truth", ...).
Status forEachDataLine(const std::string& path, const std::string& what,
                       const std::function<Status(const std::string& text, const std::string& where)>& row);
/// Writes (truncates) a file; error names the path.
Status writeTextFile(const std::string& path, const std::string& text);

}  // namespace dataset_text
}  // namespace hermes
