// Byte-exact encoders shared by every writer: little-endian binary into a buffer, the shortest
// round-tripping text of a double, "%.6f" without a negative zero. Output never depends on the
// locale, the host's byte order or rounding noise.
#pragma once

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <utility>

namespace flank::io {

// Little-endian binary output into a byte buffer.
class Bytes {
 public:
  void u8(std::uint8_t v) { data_.push_back(static_cast<char>(v)); }
  void u16(std::uint16_t v) { le(v, 2); }
  void u32(std::uint32_t v) { le(v, 4); }
  void i32(std::int32_t v) { le(static_cast<std::uint32_t>(v), 4); }
  void f32(double v) {
    const float f = to_float(v);
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    le(bits, 4);
  }
  void f64(double v) {
    std::uint64_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    le(bits, 8);
  }
  void text(const std::string& s) { data_ += s; }
  // Room for this many more bytes: a writer that knows its size appends without regrowing.
  void reserve(std::size_t more) { data_.reserve(data_.size() + more); }
  const std::string& str() const { return data_; }
  std::string take() && { return std::move(data_); }

 private:
  // Out-of-range values become ±inf without an overflow exception (Debug tests trap them).
  static float to_float(double v) {
    if (std::isnan(v)) return std::numeric_limits<float>::quiet_NaN();
    if (std::abs(v) > std::numeric_limits<float>::max())
      return v > 0 ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::infinity();
    return static_cast<float>(v);
  }
  // One append per value, not one per byte: the envelopes of a blade face are 15 MB.
  void le(std::uint64_t v, int bytes) {
    char out[8];
    for (int k = 0; k < bytes; ++k) out[k] = static_cast<char>((v >> (8 * k)) & 0xffu);
    data_.append(out, static_cast<std::size_t>(bytes));
  }
  std::string data_;
};

// Shortest text that reads back to the same double.
inline std::string shortest(double v) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, v);
  return std::string(buffer, result.ptr);
}

// "%.6f" without a negative zero, so that output does not depend on rounding noise.
inline std::string fixed6(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.6f", v);
  if (std::strcmp(buffer, "-0.000000") == 0) return "0.000000";
  return buffer;
}

// A file name's extension in lower case (".STL" → ".stl"): formats are picked by it.
inline std::string lower_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext)
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  return ext;
}

// One line of text for a file or a message: control characters become blanks.
inline std::string one_line(const std::string& s) {
  std::string out;
  for (char c : s) out += (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) ? ' ' : c;
  return out;
}

}  // namespace flank::io
