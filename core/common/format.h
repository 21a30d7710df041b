// Small text and time helpers shared by the core, the drivers and the server, so that each is
// written once: numbers as printf formats them, image sizes, and the wall-clock time.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

namespace stevi {

// A number for messages and tables: whole numbers in full ("640", "100000000"), others as
// printf's %g ("0.5", "1e-06").
std::string FormatNumber(double value);
// The whole of `text` as a finite number ("0.5", "86400", "-1e-3"); nullopt for anything else
// (empty, trailing characters, "nan", "inf", out of range).
std::optional<double> ParseNumber(std::string_view text);
// printf's %.*f: Fixed(0.123456, 3) is "0.123".
std::string Fixed(double value, int digits);
// "640x480".
std::string SizeText(int width, int height);
inline std::string SizeText(const cv::Size& size) { return SizeText(size.width, size.height); }
// Nanoseconds since the Unix epoch, by the system clock.
int64_t UnixNowNs();

}  // namespace stevi
