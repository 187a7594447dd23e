// The colours of patches, shared by design.ply and report.html so that a patch has the same
// colour in every picture of a run.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

namespace flank::report {

using Rgb = std::array<std::uint8_t, 3>;

// Distinct, colour-blind-friendly hues (Tableau 10 without its pink, which is near magenta).
inline constexpr std::array<Rgb, 11> kPalette = {{{31, 119, 180},
                                                 {255, 127, 14},
                                                 {44, 160, 44},
                                                 {214, 39, 40},
                                                 {148, 103, 189},
                                                 {140, 86, 75},
                                                 {127, 127, 127},
                                                 {188, 189, 34},
                                                 {23, 190, 207},
                                                 {174, 199, 232},
                                                 {255, 187, 120}}};
// Uncovered area: magenta, far from every hue of the palette.
inline constexpr Rgb kUncovered = {255, 0, 255};

inline const Rgb& patch_colour(int id) {
  return id < 0 ? kUncovered : kPalette[static_cast<std::size_t>(id) % kPalette.size()];
}

}  // namespace flank::report
