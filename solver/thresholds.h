// The one tolerance a user gives, turned into every threshold of the automatic decomposition
// that it implies, in one place (DESIGN "Real surfaces are not exact envelopes"): candidates
// are judged by what they cover within tolerance, so every gate is a multiple of it, never an
// exact-envelope threshold.
#pragma once

#include <string>

namespace flank {

struct Thresholds {
  double tolerance = 0.0;  // τ: Ω within τ of Φ covers it; trims cut what is beyond
  // A sweep goes on while its start cutter still fits the line's footpoint distances within
  // this: beyond 2τ no refit of the profile brings the sweep back within τ, below it the fit
  // has the room to (a line is propagated before its cutter is optimised).
  double sweep_misfit = 0.0;
  // A candidate line's footpoint distances must fit a cutter of its kind within this (rms)
  // where it starts: otherwise not even its first position is cut within tolerance.
  double line_misfit = 0.0;
  // A candidate line is grown with the simplest allowed cutter kind that fits its footpoint
  // distances within this (rms): a profile with fewer coefficients is pinned down by the fit
  // where a free-form one wanders along the radius ↔ offset valley.
  double kind_misfit = 0.0;
  // A simpler cutter kind is tried in place of a chosen patch's fitted one when its
  // least-squares sphere radii stay within this of the fitted radii everywhere; refitted, it
  // replaces it when it cuts the same surface (finish_patch). Not a bound on how far Ω moves:
  // the refit moves the motion along the radius ↔ offset valley to absorb the difference (the
  // exact cone part's barrels are 2–13τ from any cone). A bound on what the tries cost, each a
  // fit: over the 17 coverage cases 146 tries within 16τ kept 16, 15 of them within 8τ
  // (docs/performance-history.md, fifteenth part).
  double simplify = 0.0;
  // No sphere of the cutter, anywhere along it, may reach deeper into Φ than this.
  double gouge = 0.0;

  std::string validate() const;
};

// The thresholds of tolerance τ (absolute, in the mesh's units).
Thresholds thresholds_for(double tolerance);

}  // namespace flank
