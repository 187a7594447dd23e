// Scan noise of the design surface (DESIGN "Real surfaces are not exact envelopes"): a scanned or
// re-meshed face carries noise on its vertices. Its normals then tilt by σ / (edge length) from
// triangle to triangle, which no movability or trim can see past: a noise of two thirds of the
// tolerance tilts them by degrees and puts a few percent of the samples out of tolerance
// anywhere. flank measures the noise, and where it matters the solver works on a smoothed copy
// of Φ, while errors and coverage are reported against Φ as given.
#pragma once

#include "kernels/mesh.h"

namespace flank {

struct NoiseEstimate {
  double sigma = 0.0;  // robust standard deviation of the vertices off a smooth surface
  int vertices = 0;    // vertices that had enough neighbours to be measured
};

// Every vertex against the quadric height field (in its normal frame) fitted to its 2-ring
// neighbours: σ from the median absolute deviation of the residuals, corrected for the fit's
// own leverage. On a smooth surface meshed finely the residual is the third-order term
// (~1e-6 of the diagonal on the test blades); on a scan it is the noise.
NoiseEstimate estimate_noise(const Mesh& mesh);

// Φ with every vertex moved along its normal onto the quadric fitted to its `rings`-ring,
// `passes` times: a local least-squares (MLS) projection that keeps a smooth surface in place
// to third order in the neighbourhood's size (a plane exactly). Measured on a 60 × 60
// cylinder with 2-rings: the noise's rms falls 2.15× in one pass, 2.65× in two; on the test
// barrel envelope, 4-rings 4 times leave 0.18 of it. Next to Φ's boundary a one-sided
// neighbourhood averages out much less.
Mesh smooth_surface(const Mesh& mesh, int passes = 2, int rings = 2);

}  // namespace flank
