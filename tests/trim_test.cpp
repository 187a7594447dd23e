// Trimming against hand-built error grids whose best rectangle is known by construction, and
// against a brute force over every rectangle of small random grids; restricting a cutter to a
// part of its length against the radii of that part.
#include "solver/trim.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "kernels/bspline.h"

namespace flank {
namespace {

constexpr double kTol = 1e-3;

// A rows × cols grid whose every sample is within tolerance: Ω exists and lies over Φ with no
// error, every sphere just touches Φ, every row sweeps on.
ErrorGrid within_grid(int rows, int cols) {
  ErrorGrid g;
  g.rows = rows, g.cols = cols;
  const auto n = static_cast<std::size_t>(rows) * cols;
  g.sphere_error = VecX::Zero(static_cast<Eigen::Index>(n));
  g.interior.assign(n, 1);
  g.faces.assign(n, 0);
  g.directions = Points::Zero(static_cast<Eigen::Index>(n), 3);
  g.directions.col(2).setOnes();
  g.omega = Points::Zero(static_cast<Eigen::Index>(n), 3);
  g.omega_valid.assign(n, 1);
  g.omega_interior.assign(n, 1);
  g.error = VecX::Zero(static_cast<Eigen::Index>(n));
  g.sweeps.assign(static_cast<std::size_t>(rows), 1);
  return g;
}

// Ω over Φ, three tolerances off.
void set_outside(ErrorGrid& g, int i, int j) {
  const std::size_t k = g.index(i, j);
  g.omega_valid[k] = 1, g.omega_interior[k] = 1, g.interior[k] = 1;
  g.error(static_cast<Eigen::Index>(k)) = 3 * kTol;
}
// Ω's point and the centre's footpoint both beyond Φ's edge.
void set_overhang(ErrorGrid& g, int i, int j) {
  const std::size_t k = g.index(i, j);
  g.omega_interior[k] = 0;
  g.interior[k] = 0;
  g.error(static_cast<Eigen::Index>(k)) = 0.0;
}
void set_outside_row(ErrorGrid& g, int i) {
  for (int j = 0; j < g.cols; ++j) set_outside(g, i, j);
}
void set_outside_col(ErrorGrid& g, int j) {
  for (int i = 0; i < g.rows; ++i) set_outside(g, i, j);
}

int count_class(const ErrorGrid& g, const TrimRange& r, SampleClass c) {
  const std::vector<SampleClass> cls = classify_samples(g, kTol);
  int n = 0;
  for (int i = r.row0; i <= r.row1; ++i)
    for (int j = r.col0; j <= r.col1; ++j) n += cls[g.index(i, j)] == c;
  return n;
}

// A range is consistent with its grid: in bounds, nothing out of tolerance inside it, and
// `within` is the count of samples within tolerance inside it.
void expect_consistent(const ErrorGrid& g, const TrimRange& r) {
  ASSERT_FALSE(r.empty);
  EXPECT_LE(0, r.row0);
  EXPECT_LE(r.row0, r.row1);
  EXPECT_LT(r.row1, g.rows);
  EXPECT_LE(0, r.col0);
  EXPECT_LE(r.col0, r.col1);
  EXPECT_LT(r.col1, g.cols);
  EXPECT_EQ(count_class(g, r, SampleClass::outside), 0);
  EXPECT_EQ(count_class(g, r, SampleClass::within), r.within);
}

bool same_range(const TrimRange& a, const TrimRange& b) {
  return a.empty == b.empty && a.row0 == b.row0 && a.row1 == b.row1 && a.col0 == b.col0 &&
         a.col1 == b.col1 && a.within == b.within;
}

// The grid builders above mean what they say (the rules of classify_samples).
TEST(Trim, GridBuildersClassifyAsIntended) {
  ErrorGrid g = within_grid(2, 3);
  set_outside(g, 0, 1);
  set_overhang(g, 0, 2);
  const std::vector<SampleClass> cls = classify_samples(g, kTol);
  EXPECT_EQ(cls[g.index(0, 0)], SampleClass::within);
  EXPECT_EQ(cls[g.index(0, 1)], SampleClass::outside);
  EXPECT_EQ(cls[g.index(0, 2)], SampleClass::overhang);
  // The tolerance is inclusive; a sphere reaching into Φ deeper than it makes a sample outside
  // even where Ω is exact.
  g.error(static_cast<Eigen::Index>(g.index(1, 0))) = -kTol;
  g.sphere_error(static_cast<Eigen::Index>(g.index(1, 1))) = -1.5 * kTol;
  const std::vector<SampleClass> cls2 = classify_samples(g, kTol);
  EXPECT_EQ(cls2[g.index(1, 0)], SampleClass::within);
  EXPECT_EQ(cls2[g.index(1, 1)], SampleClass::outside);
}

TEST(Trim, AllWithinGivesTheFullRectangle) {
  const ErrorGrid g = within_grid(12, 8);
  const TrimRange r = find_trim(g, kTol);
  EXPECT_TRUE(r.full(g));
  EXPECT_EQ(r.within, 12 * 8);
  EXPECT_EQ(r.rows(), 12);
  EXPECT_EQ(r.cols(), 8);
  const std::vector<TrimRange> pieces = find_pieces(g, kTol);
  ASSERT_EQ(pieces.size(), 1u);
  EXPECT_TRUE(same_range(pieces[0], r));
}

TEST(Trim, AllOutsideOrAllOverhangGivesNothing) {
  ErrorGrid g = within_grid(10, 6);
  for (int i = 0; i < g.rows; ++i) set_outside_row(g, i);
  EXPECT_TRUE(find_trim(g, kTol).empty);
  EXPECT_TRUE(find_pieces(g, kTol).empty());
  // Overhang alone is worth nothing either: a cut must cut some of Φ.
  for (int i = 0; i < g.rows; ++i)
    for (int j = 0; j < g.cols; ++j) set_overhang(g, i, j);
  EXPECT_TRUE(find_trim(g, kTol).empty);
  EXPECT_TRUE(find_pieces(g, kTol).empty());
}

// A row out of tolerance in the middle splits the sweep: the larger side is the trim, and both
// sides are pieces, best first, disjoint in rows.
TEST(Trim, BadMiddleRowSplitsIntoTwoPieces) {
  ErrorGrid g = within_grid(20, 6);
  set_outside_row(g, 12);
  const TrimRange r = find_trim(g, kTol);
  expect_consistent(g, r);
  EXPECT_EQ(r.row0, 0);
  EXPECT_EQ(r.row1, 11);
  EXPECT_EQ(r.col0, 0);
  EXPECT_EQ(r.col1, 5);
  EXPECT_EQ(r.within, 12 * 6);
  EXPECT_FALSE(r.full(g));

  const std::vector<TrimRange> pieces = find_pieces(g, kTol);
  ASSERT_EQ(pieces.size(), 2u);
  EXPECT_TRUE(same_range(pieces[0], r));
  expect_consistent(g, pieces[1]);
  EXPECT_EQ(pieces[1].row0, 13);
  EXPECT_EQ(pieces[1].row1, 19);
  EXPECT_EQ(pieces[1].within, 7 * 6);
  EXPECT_LT(pieces[0].row1, pieces[1].row0);

  // Mirrored: the larger side is after the bad row, and still comes first.
  ErrorGrid m = within_grid(20, 6);
  set_outside_row(m, 7);
  const std::vector<TrimRange> mp = find_pieces(m, kTol);
  ASSERT_EQ(mp.size(), 2u);
  EXPECT_EQ(mp[0].row0, 8);
  EXPECT_EQ(mp[0].row1, 19);
  EXPECT_EQ(mp[1].row0, 0);
  EXPECT_EQ(mp[1].row1, 6);
}

// The smaller side is a piece only when it holds at least min_fraction of the best piece's
// samples within tolerance: the bound is inclusive.
TEST(Trim, SmallerPieceNeedsMinFractionOfTheBest) {
  // Rows 0..7 (48 within), bad row 8, rows 9..12 (24 within): exactly half.
  ErrorGrid g = within_grid(13, 6);
  set_outside_row(g, 8);
  PieceOptions o;
  o.min_fraction = 0.5;
  std::vector<TrimRange> pieces = find_pieces(g, kTol, o);
  ASSERT_EQ(pieces.size(), 2u);
  EXPECT_EQ(pieces[0].within, 48);
  EXPECT_EQ(pieces[1].within, 24);
  o.min_fraction = 0.51;
  EXPECT_EQ(find_pieces(g, kTol, o).size(), 1u);
  // One sample of the small side beyond Φ's edge: 23 < 24, it is dropped.
  o.min_fraction = 0.5;
  set_overhang(g, 10, 2);
  pieces = find_pieces(g, kTol, o);
  ASSERT_EQ(pieces.size(), 1u);
  EXPECT_EQ(pieces[0].row1, 7);
}

// Three pieces: best first, the others by worth, ties in their order along t; max_pieces cuts
// the list; all disjoint in rows.
TEST(Trim, PiecesAreBestFirstDisjointAndCapped) {
  // Rows 0..5 (6 rows), bad 6, rows 7..14 (8), bad 15, rows 16..21 (6).
  ErrorGrid g = within_grid(22, 5);
  set_outside_row(g, 6);
  set_outside_row(g, 15);
  PieceOptions o;
  o.max_pieces = 5;
  const std::vector<TrimRange> pieces = find_pieces(g, kTol, o);
  ASSERT_EQ(pieces.size(), 3u);
  EXPECT_EQ(pieces[0].row0, 7);
  EXPECT_EQ(pieces[0].row1, 14);
  EXPECT_EQ(pieces[1].row0, 0);  // tie with rows 16..21: the earlier along t first
  EXPECT_EQ(pieces[1].row1, 5);
  EXPECT_EQ(pieces[2].row0, 16);
  EXPECT_EQ(pieces[2].row1, 21);
  for (std::size_t a = 0; a < pieces.size(); ++a) {
    expect_consistent(g, pieces[a]);
    if (a > 0) {
      EXPECT_GE(pieces[a - 1].within, pieces[a].within);
    }
    for (std::size_t b = a + 1; b < pieces.size(); ++b)
      EXPECT_TRUE(pieces[a].row1 < pieces[b].row0 || pieces[b].row1 < pieces[a].row0) << a << " " << b;
  }
  // Make the last piece the larger of the two: it then comes second.
  set_outside_row(g, 1);  // rows 2..5 are left: 4 rows
  const std::vector<TrimRange> p2 = find_pieces(g, kTol, o);
  ASSERT_EQ(p2.size(), 3u);
  EXPECT_EQ(p2[1].row0, 16);
  EXPECT_EQ(p2[2].row0, 2);
  o.max_pieces = 2;
  const std::vector<TrimRange> capped = find_pieces(g, kTol, o);
  ASSERT_EQ(capped.size(), 2u);
  EXPECT_TRUE(same_range(capped[0], p2[0]));
  EXPECT_TRUE(same_range(capped[1], p2[1]));
}

// A column out of tolerance near one end of the cutter: the rectangle stops before it.
TEST(Trim, BadColumnTrimsAlongTheCutter) {
  ErrorGrid g = within_grid(10, 12);
  set_outside_col(g, 10);
  TrimRange r = find_trim(g, kTol);
  expect_consistent(g, r);
  EXPECT_EQ(r.row0, 0);
  EXPECT_EQ(r.row1, 9);
  EXPECT_EQ(r.col0, 0);
  EXPECT_EQ(r.col1, 9);
  EXPECT_EQ(r.within, 100);

  // One bad sample in that column is enough: all rows of columns 0..9 (100) beat all columns
  // of rows 0..4 (60).
  ErrorGrid h = within_grid(10, 12);
  set_outside(h, 5, 10);
  r = find_trim(h, kTol);
  expect_consistent(h, r);
  EXPECT_EQ(r.col1, 9);
  EXPECT_EQ(r.rows(), 10);

  // Near the tip (column 1): the rectangle starts after it.
  ErrorGrid t = within_grid(10, 12);
  set_outside_col(t, 1);
  r = find_trim(t, kTol);
  expect_consistent(t, r);
  EXPECT_EQ(r.col0, 2);
  EXPECT_EQ(r.col1, 11);
}

// Pure overhang beyond the last column within tolerance: exactly one such column is kept on
// each side (the last sample inside Φ may be a spacing short of its edge), whichever side the
// search's tie order favours.
TEST(Trim, KeepsExactlyOneOverhangColumnPastEachEnd) {
  for (int before : {0, 1, 3})
    for (int after : {0, 1, 4}) {
      const int cols = before + 5 + after;
      ErrorGrid g = within_grid(8, cols);
      for (int i = 0; i < g.rows; ++i) {
        for (int j = 0; j < before; ++j) set_overhang(g, i, j);
        for (int j = before + 5; j < cols; ++j) set_overhang(g, i, j);
      }
      const TrimRange r = find_trim(g, kTol);
      SCOPED_TRACE(::testing::Message() << "before " << before << " after " << after);
      expect_consistent(g, r);
      EXPECT_EQ(r.col0, before > 0 ? before - 1 : 0);
      EXPECT_EQ(r.col1, after > 0 ? before + 5 : cols - 1);
      EXPECT_EQ(r.within, 8 * 5);
      EXPECT_EQ(r.row0, 0);
      EXPECT_EQ(r.row1, 7);
    }
  // An overhang column followed by one out of tolerance: the overhang one is kept.
  ErrorGrid g = within_grid(8, 9);
  for (int i = 0; i < g.rows; ++i) set_overhang(g, i, 6);
  set_outside_col(g, 7);
  const TrimRange r = find_trim(g, kTol);
  expect_consistent(g, r);
  EXPECT_EQ(r.col0, 0);
  EXPECT_EQ(r.col1, 6);
}

TEST(Trim, KeepsExactlyOneOverhangRowPastEachEnd) {
  for (int before : {0, 1, 3})
    for (int after : {0, 1, 4}) {
      const int rows = before + 6 + after;
      ErrorGrid g = within_grid(rows, 5);
      for (int j = 0; j < g.cols; ++j) {
        for (int i = 0; i < before; ++i) set_overhang(g, i, j);
        for (int i = before + 6; i < rows; ++i) set_overhang(g, i, j);
      }
      const TrimRange r = find_trim(g, kTol);
      SCOPED_TRACE(::testing::Message() << "before " << before << " after " << after);
      expect_consistent(g, r);
      EXPECT_EQ(r.row0, before > 0 ? before - 1 : 0);
      EXPECT_EQ(r.row1, after > 0 ? before + 6 : rows - 1);
      EXPECT_EQ(r.within, 6 * 5);
      EXPECT_EQ(r.col0, 0);
      EXPECT_EQ(r.col1, 4);
    }
}

// A row where the motion stalls or turns back (sweeps = 0) is out, even where its samples are
// within tolerance: the rectangle never holds it.
TEST(Trim, StalledRowIsNeverInsideARectangle) {
  ErrorGrid g = within_grid(12, 5);
  g.sweeps[6] = 0;
  const std::vector<TrimRange> pieces = find_pieces(g, kTol);
  ASSERT_EQ(pieces.size(), 2u);
  EXPECT_EQ(pieces[0].row0, 0);
  EXPECT_EQ(pieces[0].row1, 5);
  EXPECT_EQ(pieces[1].row0, 7);
  EXPECT_EQ(pieces[1].row1, 11);
  // A stall at the last row, after rows of overhang.
  ErrorGrid e = within_grid(12, 5);
  for (int i = 8; i < 12; ++i)
    for (int j = 0; j < 5; ++j) set_overhang(e, i, j);
  e.sweeps[9] = 0;
  const TrimRange r = find_trim(e, kTol);
  expect_consistent(e, r);
  EXPECT_EQ(r.row1, 8);

  // Random grids: no piece holds a stalled row.
  std::mt19937 rng(20240611);
  for (int trial = 0; trial < 200; ++trial) {
    ErrorGrid h = within_grid(14, 6);
    for (int i = 0; i < h.rows; ++i)
      for (int j = 0; j < h.cols; ++j) {
        const unsigned u = rng() % 10;
        if (u == 0) set_outside(h, i, j);
        if (u == 1 || u == 2) set_overhang(h, i, j);
      }
    for (int i = 0; i < h.rows; ++i) h.sweeps[i] = rng() % 5 != 0;
    PieceOptions o;
    o.min_rows = 2, o.min_cols = 2, o.min_fraction = 0.0, o.max_pieces = 10;
    for (const TrimRange& p : find_pieces(h, kTol, o))
      for (int i = p.row0; i <= p.row1; ++i) ASSERT_TRUE(h.sweeps[i]) << "trial " << trial << " row " << i;
  }
}

// Untrusted samples count as overhang, whatever their error: the same trim as with those
// samples made overhang, and a within sample made untrusted stops counting.
TEST(Trim, UntrustedSamplesBehaveAsOverhang) {
  ErrorGrid a = within_grid(10, 9);
  ErrorGrid b = within_grid(10, 9);
  a.untrusted.assign(a.error.size(), 0);
  // Columns 7 and 8 out of tolerance but untrusted (a smoothed scan next to Φ's edge); a
  // sphere that gouges there is not believed either.
  for (int i = 0; i < a.rows; ++i)
    for (int j = 7; j < 9; ++j) {
      set_outside(a, i, j);
      a.untrusted[a.index(i, j)] = 1;
      set_overhang(b, i, j);
    }
  a.sphere_error(static_cast<Eigen::Index>(a.index(3, 8))) = -10 * kTol;
  const TrimRange ra = find_trim(a, kTol), rb = find_trim(b, kTol);
  expect_consistent(a, ra);
  EXPECT_TRUE(same_range(ra, rb));
  EXPECT_EQ(ra.col1, 7);  // one overhang column kept past the last one within
  EXPECT_EQ(ra.within, 10 * 7);

  // Untrusted within samples are worth nothing.
  ErrorGrid c = within_grid(10, 9);
  c.untrusted.assign(c.error.size(), 0);
  c.untrusted[c.index(4, 4)] = 1;
  EXPECT_EQ(find_trim(c, kTol).within, 10 * 9 - 1);
  EXPECT_TRUE(find_trim(c, kTol).full(c));
}

// A stalled row (sweeps = 0) whose samples are all untrusted is still out: `untrusted` says
// Φ's verdict there is noise, while a stall is the motion's own and does not depend on Φ
// (sweeps turn back near Φ's edge, where a smoothed scan's samples are untrusted).
TEST(Trim, StalledUntrustedRowIsNeverInsideARectangle) {
  ErrorGrid g = within_grid(12, 5);
  g.untrusted.assign(g.error.size(), 0);
  for (int i = 10; i < 12; ++i)
    for (int j = 0; j < 5; ++j) {
      set_overhang(g, i, j);
      g.untrusted[g.index(i, j)] = 1;
    }
  g.sweeps[10] = 0;
  const TrimRange r = find_trim(g, kTol);
  ASSERT_FALSE(r.empty);
  EXPECT_EQ(r.row1, 9);  // not 10, the stalled row
}

// Rows and columns below min_rows / min_cols make no rectangle.
TEST(Trim, MinRowsAndMinColsAreRespected) {
  // Within: a block of 3 rows between rows out of tolerance.
  ErrorGrid g = within_grid(9, 6);
  for (int i : {0, 1, 2, 6, 7, 8}) set_outside_row(g, i);
  PieceOptions o;
  o.min_rows = 4;
  EXPECT_TRUE(find_trim(g, kTol, o).empty);
  o.min_rows = 3;
  TrimRange r = find_trim(g, kTol, o);
  expect_consistent(g, r);
  EXPECT_EQ(r.row0, 3);
  EXPECT_EQ(r.row1, 5);

  // Within: a block of 2 columns between columns out of tolerance.
  ErrorGrid c = within_grid(8, 7);
  for (int j : {0, 1, 4, 5, 6}) set_outside_col(c, j);
  o = PieceOptions{};
  o.min_cols = 3;
  EXPECT_TRUE(find_trim(c, kTol, o).empty);
  o.min_cols = 2;
  r = find_trim(c, kTol, o);
  expect_consistent(c, r);
  EXPECT_EQ(r.col0, 2);
  EXPECT_EQ(r.col1, 3);

  // Random grids: every range has at least min_rows × min_cols samples.
  std::mt19937 rng(7);
  for (int trial = 0; trial < 300; ++trial) {
    ErrorGrid h = within_grid(9, 7);
    for (int i = 0; i < h.rows; ++i)
      for (int j = 0; j < h.cols; ++j)
        if (rng() % 6 == 0) set_outside(h, i, j);
    PieceOptions p;
    p.min_rows = 3 + static_cast<int>(rng() % 3);
    p.min_cols = 2 + static_cast<int>(rng() % 3);
    for (const TrimRange& q : find_pieces(h, kTol, p)) {
      EXPECT_GE(q.rows(), p.min_rows) << "trial " << trial;
      EXPECT_GE(q.cols(), p.min_cols) << "trial " << trial;
    }
  }
}

// When the samples within tolerance span fewer than min_rows rows and the rows around them are
// pure overhang, the final shrink ("plus one of pure overhang past each end") stops at
// min_rows × min_cols instead of cutting to rows 4..6 (3 rows) with min_rows = 4.
TEST(Trim, ShrinkKeepsMinRowsAndMinCols) {
  ErrorGrid g = within_grid(10, 6);
  for (int i = 0; i < g.rows; ++i)
    if (i != 5)
      for (int j = 0; j < g.cols; ++j) set_overhang(g, i, j);
  PieceOptions o;
  o.min_rows = 4;
  const TrimRange r = find_trim(g, kTol, o);
  ASSERT_FALSE(r.empty);
  EXPECT_GE(r.rows(), o.min_rows);

  ErrorGrid c = within_grid(8, 9);
  for (int i = 0; i < c.rows; ++i)
    for (int j = 0; j < c.cols; ++j)
      if (j != 4) set_overhang(c, i, j);
  o = PieceOptions{};
  o.min_cols = 4;
  const TrimRange rc = find_trim(c, kTol, o);
  ASSERT_FALSE(rc.empty);
  EXPECT_GE(rc.cols(), o.min_cols);
}

// Ties keep the first found, column ranges outermost: of two rectangles of equal worth the one
// whose first column is lower, even when the other starts rows earlier. A = rows 0..3 ×
// columns 4..6 and B = rows 6..9 × columns 0..2 both hold 12 samples within tolerance: B.
TEST(Trim, TiesKeepTheFirstFoundColumnsFirst) {
  ErrorGrid g = within_grid(10, 7);
  for (int i = 0; i < g.rows; ++i)
    for (int j = 0; j < g.cols; ++j) {
      const bool a = i <= 3 && j >= 4, b = i >= 6 && j <= 2;
      if (!a && !b) set_outside(g, i, j);
    }
  PieceOptions o;
  o.min_rows = 4, o.min_cols = 3;
  const TrimRange r = find_trim(g, kTol, o);
  ASSERT_FALSE(r.empty);
  EXPECT_EQ(r.within, 12);
  // The documented order: the lowest first column wins, B.
  EXPECT_EQ(r.row0, 6);
  EXPECT_EQ(r.col0, 0);
}

// find_trim against a brute force over every rectangle of g (by prefix sums): the same worth,
// nothing out of tolerance inside, and its worth is what it holds; nothing where no rectangle
// of the minimum size holds a sample within tolerance.
void expect_best_rectangle(const ErrorGrid& g, const PieceOptions& o) {
  const int rows = g.rows, cols = g.cols;
  const std::vector<SampleClass> cls = classify_samples(g, kTol);
  // P[i][j] counts the class in rows < i, columns < j.
  const auto prefix = [&](SampleClass c) {
    std::vector<int> P(static_cast<std::size_t>((rows + 1) * (cols + 1)), 0);
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j)
        P[static_cast<std::size_t>((i + 1) * (cols + 1) + j + 1)] =
            P[static_cast<std::size_t>(i * (cols + 1) + j + 1)] + P[static_cast<std::size_t>((i + 1) * (cols + 1) + j)] -
            P[static_cast<std::size_t>(i * (cols + 1) + j)] + (cls[g.index(i, j)] == c);
    return P;
  };
  const std::vector<int> W = prefix(SampleClass::within), X = prefix(SampleClass::outside);
  const auto count = [&](const std::vector<int>& P, int r0, int r1, int c0, int c1) {
    const auto at = [&](int i, int j) { return P[static_cast<std::size_t>(i * (cols + 1) + j)]; };
    return at(r1 + 1, c1 + 1) - at(r0, c1 + 1) - at(r1 + 1, c0) + at(r0, c0);
  };
  int best = 0;
  for (int r0 = 0; r0 < rows; ++r0)
    for (int r1 = r0 + o.min_rows - 1; r1 < rows; ++r1)
      for (int c0 = 0; c0 < cols; ++c0)
        for (int c1 = c0 + o.min_cols - 1; c1 < cols; ++c1)
          if (count(X, r0, r1, c0, c1) == 0) best = std::max(best, count(W, r0, r1, c0, c1));
  const TrimRange r = find_trim(g, kTol, o);
  if (best == 0) {
    EXPECT_TRUE(r.empty);
    return;
  }
  expect_consistent(g, r);
  EXPECT_EQ(r.within, best);
}

// The best rectangle of small random grids.
TEST(Trim, FindTrimIsTheBestRectangle) {
  std::mt19937 rng(12345);
  for (int trial = 0; trial < 300; ++trial) {
    const int rows = 5 + static_cast<int>(rng() % 5), cols = 3 + static_cast<int>(rng() % 5);
    ErrorGrid g = within_grid(rows, cols);
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) {
        const unsigned u = rng() % 8;
        if (u == 0) set_outside(g, i, j);
        if (u == 1 || u == 2) set_overhang(g, i, j);
      }
    PieceOptions o;
    o.min_rows = 2 + static_cast<int>(rng() % 3);
    o.min_cols = 2 + static_cast<int>(rng() % 2);
    SCOPED_TRACE(::testing::Message() << "trial " << trial);
    expect_best_rectangle(g, o);
  }
}

// The same on grids the size of a finished patch's and mostly within tolerance (a few samples
// out, overhang at the ends), where the search skips the column ranges that cannot beat its
// best so far.
TEST(Trim, FindTrimIsTheBestRectangleOnLargeGridsMostlyWithin) {
  std::mt19937 rng(777);
  for (int trial = 0; trial < 60; ++trial) {
    const int rows = 20 + static_cast<int>(rng() % 60), cols = 8 + static_cast<int>(rng() % 24);
    ErrorGrid g = within_grid(rows, cols);
    const unsigned out_per_mille = 2 + rng() % 40;
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) {
        if (rng() % 1000 < out_per_mille) set_outside(g, i, j);
        else if (j == 0 || j == cols - 1 || i < 2) set_overhang(g, i, j);
      }
    if (trial % 3 == 0) set_outside_row(g, static_cast<int>(rng() % static_cast<unsigned>(rows)));
    PieceOptions o;
    o.min_rows = 2 + static_cast<int>(rng() % 6);
    o.min_cols = 2 + static_cast<int>(rng() % 4);
    SCOPED_TRACE(::testing::Message() << "trial " << trial << ", " << rows << " x " << cols);
    expect_best_rectangle(g, o);
  }
}

// --- restrict_cutter ---------------------------------------------------------------------

// Cutter::fit adds a ridge of 1e-12 of its normal matrix's diagonal, so a profile of the
// same kind comes back to about 1e-12 of its radius, not to the last bit (measured: cylinder
// 1.02e-12, cone 9.0e-13, barrel 8.1e-13 relative): the bound is three times that.
constexpr double kExact = 3e-12;

void expect_same_radii(const Cutter& whole, const Cutter& part, double s0, double s1) {
  for (int k = 0; k <= 1000; ++k) {
    const double u = k / 1000.0, s = s0 + u * (s1 - s0);
    ASSERT_NEAR(part.radius(u), whole.radius(s), kExact * whole.radius(s)) << "u " << u;
    // d′ carries the same coefficient error times the basis derivatives (up to 2 · degree).
    ASSERT_NEAR(part.slope(u), whole.slope(s) * (s1 - s0), 10 * kExact * whole.radius(s)) << "u " << u;
  }
}

TEST(RestrictCutter, CylinderConeAndBarrelKeepTheRadiiOfTheKeptPart) {
  const double L = 30.0, s0 = 0.2, s1 = 0.75;
  Cutter cyl;
  cyl.kind = CutterKind::cylinder, cyl.length = L, cyl.coeffs = VecX::Constant(1, 5.0);
  const Cutter cone = cone_from_end_radii(L, 4.0, 7.0);
  Cutter barrel;
  barrel.kind = CutterKind::barrel, barrel.length = L;
  barrel.coeffs.resize(3);
  barrel.coeffs << 5.0, 6.5, 5.2;
  for (const Cutter* c : std::initializer_list<const Cutter*>{&cyl, &cone, &barrel}) {
    SCOPED_TRACE(to_string(c->kind));
    const Cutter part = restrict_cutter(*c, s0, s1);
    EXPECT_EQ(part.kind, c->kind);
    EXPECT_NEAR(part.length, L * (s1 - s0), 1e-12 * L);
    EXPECT_TRUE(part.valid());
    expect_same_radii(*c, part, s0, s1);
  }
  // The part of a cone is the same cone between the meridian's radii at z = s0 L and s1 L.
  const Vec2 ends = restrict_cutter(cone, s0, s1).cone_end_radii();
  const double k = (7.0 - 4.0) / L;
  EXPECT_NEAR(ends(0), 4.0 + k * s0 * L, 1e-10);
  EXPECT_NEAR(ends(1), 4.0 + k * s1 * L, 1e-10);
  // The whole range gives the cutter back.
  expect_same_radii(barrel, restrict_cutter(barrel, 0.0, 1.0), 0.0, 1.0);
}

// A spline profile is refitted on the part, which may overshoot: with radius bounds its
// coefficients, and so d(s) everywhere, stay within them.
TEST(RestrictCutter, SplineStaysWithinTheRadiusBounds) {
  Cutter step;
  step.kind = CutterKind::spline, step.length = 25.0;
  step.coeffs.resize(kSplineProfileCoefficients);
  step.coeffs << 5, 5, 5, 5, 5, 8, 8, 8, 8, 8;  // a steep rise: least squares rings on it
  const double lo = 5.0, hi = 8.0;
  int unbounded_out = 0;
  for (auto [s0, s1] : {std::pair{0.3, 0.9}, std::pair{0.0, 0.7}, std::pair{0.35, 0.65}, std::pair{0.1, 1.0}}) {
    SCOPED_TRACE(::testing::Message() << "[" << s0 << ", " << s1 << "]");
    const Cutter free = restrict_cutter(step, s0, s1);
    for (Eigen::Index k = 0; k < free.coeffs.size(); ++k)
      unbounded_out += free.coeffs(k) < lo - 1e-9 || free.coeffs(k) > hi + 1e-9;
    const Cutter part = restrict_cutter(step, s0, s1, lo, hi);
    EXPECT_EQ(part.kind, CutterKind::spline);
    ASSERT_EQ(part.coeffs.size(), kSplineProfileCoefficients);
    for (Eigen::Index k = 0; k < part.coeffs.size(); ++k) {
      EXPECT_GE(part.coeffs(k), lo);
      EXPECT_LE(part.coeffs(k), hi);
    }
    double worst = 0.0;
    for (int k = 0; k <= 1000; ++k) {
      const double u = k / 1000.0;
      ASSERT_GE(part.radius(u), lo - 1e-12) << "u " << u;
      ASSERT_LE(part.radius(u), hi + 1e-12) << "u " << u;
      worst = std::max(worst, std::abs(part.radius(u) - step.radius(s0 + u * (s1 - s0))));
    }
    // Still the same tool, near enough: a tenth of the step.
    EXPECT_LT(worst, 0.3);
  }
  // The bounds were needed: without them some refit overshoots the range.
  EXPECT_GT(unbounded_out, 0);
}

// restrict_to maps the range's rows and columns to t and s and restricts both the motion and
// the cutter there. The motion's rulings are cubic in t, so the restricted motion is the same
// surface up to fit_spline's smoothing term (1e-8 of its normal matrix): 1e-6 of the motion's
// size bounds it, where a wrong map of rows or columns would be off by a whole sample.
TEST(RestrictCutter, RestrictToMapsTheRangeToTheMotionAndCutter) {
  std::vector<Line> rulings;
  const int n = 40;
  std::vector<double> params;
  for (int i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / (n - 1);
    const Vec3 a(10 * t, 2 * t * t - t, 0.5 * t * t * t);
    const Vec3 b = a + Vec3(1.0 - 0.3 * t, 0.2 * t * t, 20.0);
    rulings.push_back({a, b});
    params.push_back(t);
  }
  const Motion motion = Motion::fit(rulings, 6, params);
  Cutter barrel;
  barrel.kind = CutterKind::barrel, barrel.length = 20.0;
  barrel.coeffs.resize(3);
  barrel.coeffs << 3.0, 3.6, 3.1;
  const ErrorGrid g = within_grid(11, 6);
  TrimRange range;
  range.row0 = 2, range.row1 = 7, range.col0 = 1, range.col1 = 4, range.empty = false;
  const PieceStart p = restrict_to(motion, barrel, range, g);
  const double t0 = 0.2, t1 = 0.7, s0 = 0.2, s1 = 0.8;
  EXPECT_EQ(p.motion.count(), motion.count());
  for (int i = 0; i <= 20; ++i)
    for (int j = 0; j <= 4; ++j) {
      const double u = i / 20.0, v = j / 4.0;
      const Vec3 want = motion.point(t0 + u * (t1 - t0), s0 + v * (s1 - s0));
      ASSERT_LT((p.motion.point(u, v) - want).norm(), 1e-6 * 20.0) << u << " " << v;
    }
  expect_same_radii(barrel, p.cutter, s0, s1);
  EXPECT_NEAR(p.cutter.length, 20.0 * (s1 - s0), 1e-12);
}

}  // namespace
}  // namespace flank
