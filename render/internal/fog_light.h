// The light reaching points in fog, kept on a lattice: fog.cpp evaluates the
// light (the transmittance rays to the lights) at the lattice points around
// a sample and interpolates their logarithms trilinearly, so neighbouring
// pixels and samples share transmittance rays. Under one directional light
// the lattice lies in light space instead (FogColumnCache): columns along
// the light, each traced once from the light's side and sampled along its
// length, so that the points of a column share one ray, and interpolated
// with their curvature across the light (ColumnBlock). A lattice point's
// or a column sample's value depends on the point alone, never on which
// pixel asked first, so tiles, threads and Slurm parts give the same image
// bit for bit. Private to render/.
//
// Thread safety: a FogLightCache belongs to one thread (Renderer::ThreadState).
#ifndef VOX_RENDER_INTERNAL_FOG_LIGHT_H_
#define VOX_RENDER_INTERNAL_FOG_LIGHT_H_

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <glm/vec3.hpp>
#include <limits>
#include <memory>
#include <vector>

#include "core/ray.h"

namespace vox::render_internal {

// Voxels by which the lattices lie off the pyramid's cell centres and
// edges along each axis: under a light along an axis, the transmittance
// rays of lattice points and columns then run through voxel centres, where
// they would run along voxel edges and corners and see the voxels on one
// side only (the fog's rim half a voxel off).
inline constexpr double kLatticeOffset = 0.5;

// The largest spacing from a sample read from a lattice to the next sample
// along the primary ray, in lattice spacings; the lattice's spacing is
// about volume.light_step over this (8 voxels by default).
inline constexpr double kLatticeSampleSpacings = 3.0;

// A lattice of spacing 2^level voxels: point i lies at (i + 1/2) 2^level +
// kLatticeOffset in grid coordinates (off the cell centres of the
// pyramid's level `level`).
struct LatticePoint {
  int32_t x, y, z, level;
  bool operator==(const LatticePoint& o) const {
    return x == o.x && y == o.y && z == o.z && level == o.level;
  }
};

// The largest log-ratio of the light at a block's corners that is
// interpolated (a factor of e). At the light's terminator (the fog's
// silhouette seen from the light) the light falls as the square root of
// the depth, so blocks there differ most; interpolating up to a factor of e
// keeps the default frames' error (docs/performance.md) and leaves far
// fewer samples to trace their own rays.
inline constexpr double kMaxLatticeLogRatio = 1.0;

// A block's eight log-lights (per channel, corner c at offset (c & 1,
// c >> 1 & 1, c >> 2 & 1)) and how they may be interpolated.
struct LatticeBlock {
  enum Shape : uint8_t {
    kGrey,   // the three channels equal at every corner: channel 0 stands for all
    kRgb,    // each channel on its own
    kSteep,  // some channel's corners differ by more than kMaxLatticeLogRatio,
             // or have light at some corners only: not interpolated
  };
  double log_light[3][8];
  Shape shape = kSteep;
  bool dark[3] = {false, false, false};  // no light at any corner (shape != kSteep)

  // Sets log_light from the corners' values and classifies them.
  void Set(const glm::dvec3 corner[8]) {
    bool grey = true;
    for (int c = 0; c < 8; ++c) {
      for (int k = 0; k < 3; ++k) log_light[k][c] = corner[c][k];
      grey = grey && corner[c].x == corner[c].y && corner[c].x == corner[c].z;
    }
    shape = grey ? kGrey : kRgb;
    for (int k = 0; k < (grey ? 1 : 3); ++k) {
      double lo = std::numeric_limits<double>::infinity(), hi = -lo;
      for (int c = 0; c < 8; ++c) {
        lo = std::min(lo, log_light[k][c]);
        hi = std::max(hi, log_light[k][c]);
      }
      dark[k] = hi == -std::numeric_limits<double>::infinity();
      if (!dark[k] && !(hi - lo <= kMaxLatticeLogRatio)) shape = kSteep;
    }
    if (grey) dark[1] = dark[2] = dark[0];
  }
};

// The trilinear interpolation of a block's eight corner values v (corner c
// at offset (c & 1, c >> 1 & 1, c >> 2 & 1)) at offsets f (0..1 per axis).
inline double Trilinear(const double* v, const glm::dvec3& f) {
  const double x00 = v[0] + f.x * (v[1] - v[0]), x10 = v[2] + f.x * (v[3] - v[2]);
  const double x01 = v[4] + f.x * (v[5] - v[4]), x11 = v[6] + f.x * (v[7] - v[6]);
  const double y0 = x00 + f.y * (x10 - x00), y1 = x01 + f.y * (x11 - x01);
  return y0 + f.z * (y1 - y0);
}

inline size_t LatticePointHash(const LatticePoint& p) {
  uint64_t h = uint64_t(int64_t(p.x)) * 0x9E3779B97F4A7C15ull;
  h ^= uint64_t(int64_t(p.y)) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
  h ^= uint64_t(int64_t(p.z)) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
  h ^= uint64_t(p.level) * 0x27D4EB2F165667C5ull;
  return size_t(h ^ (h >> 29));
}

// A block of the light-space lattice (FogColumnCache::Block): its eight
// corners' log-lights, classified as a LatticeBlock's, and the curvature of
// the log-light across the columns at its edges, from the columns beyond
// them. Across the light the optical depth to the fog's lit side is curved
// (in a round fog it grows as a square root towards the rim seen from the
// light), and the trilinear interpolation of its logarithm, straight
// between columns, sees too little depth, so too much light; the curvature
// corrects it (Interpolate). A channel's values lie together, so that a
// grey block's are read from a few cache lines.
struct ColumnBlock {
  // (no initialisers: FogColumnCache leaves a slot's bytes untouched until
  // it builds a block there, and sets every field Interpolate reads)
  LatticeBlock::Shape shape;
  bool dark[3];  // (as LatticeBlock's)
  // Whether the curvature applies: the corners may be interpolated, they
  // are not all alike, and every column of the block and beside it is
  // within kMaxLatticeLogRatio of every other (none dark, none across a
  // shadow's edge).
  bool curved;
  struct Channel {
    double log_light[8];  // corner c: column (i0 + (c & 1), j0 + (c >> 1 & 1)), sample m0 + (c >> 2)
    // The second difference of the log-light across the columns (per
    // spacing squared): curve_u along the block's edge j0 + r at sample m0
    // + m ([r + 2 m]), from columns i0 - 1..i0 + 2; curve_v along its edge
    // i0 + r, from columns j0 - 1..j0 + 2 (set only where curved).
    double curve_u[4], curve_v[4];
    double lo, hi;  // (the values' range)
  } ch[3];

  // The light inside the block at offsets f (across the columns, and along
  // them, 0..1): trilinear in the logarithm, plus where curved the
  // quadratic through the corners' values with the edges' second
  // differences (bilinear between the edges; kept within the values'
  // range). False where the corners differ too much (LatticeBlock::kSteep):
  // the caller tries finer columns.
  bool Interpolate(const glm::dvec3& f, glm::dvec3* out) const {
    if (shape == LatticeBlock::kSteep) return false;
    const int channels = shape == LatticeBlock::kGrey ? 1 : 3;
    const double bend_u = 0.5 * f.x * (f.x - 1.0), bend_v = 0.5 * f.y * (f.y - 1.0);
    for (int k = 0; k < channels; ++k) {
      if (dark[k]) {  // no light in this channel anywhere
        (*out)[k] = 0.0;
        continue;
      }
      const Channel& c = ch[k];
      double log_light = Trilinear(c.log_light, f);
      if (curved) {
        const double* cu = c.curve_u;
        const double* cv = c.curve_v;
        const double u0 = cu[0] + f.y * (cu[1] - cu[0]), u1 = cu[2] + f.y * (cu[3] - cu[2]);
        const double v0 = cv[0] + f.x * (cv[1] - cv[0]), v1 = cv[2] + f.x * (cv[3] - cv[2]);
        log_light = std::clamp(log_light + bend_u * (u0 + f.z * (u1 - u0)) + bend_v * (v0 + f.z * (v1 - v0)),
                               c.lo, c.hi);
      }
      (*out)[k] = std::exp(log_light);
    }
    if (channels == 1) out->y = out->z = out->x;
    return true;
  }
};

// The light-space lattice: optical depths along columns. Column (i, j) of
// level L samples the line through (i 2^L + kLatticeOffset) u + (j 2^L +
// kLatticeOffset) v along the light's direction (fog.cpp sets the frame u,
// v, n) every 2^L voxels, from sample
// 0 at its top, above the volume, downwards. Samples are traced kChunk at
// a time, in order from the top, each chunk from the optical depth of the
// sample before it: a sample's value depends on its column alone.
class FogColumnCache {
 public:
  static constexpr int kChunk = 16;
  // Samples kept at most; the columns start again when full.
  static constexpr size_t kMaxSamples = size_t(1) << 17;
  // Blocks kept together, at most (as FogLightCache's).
  static constexpr size_t kMaxBlocks = size_t(1) << 12;
  // Column indices kept (larger ones are not: the caller traces its own rays).
  static constexpr int64_t kMaxIndex = int64_t(1) << 29;
  // Sample indices kept.
  static constexpr int kMaxSample = 1 << 24;
  // Bytes a kept block takes at most.
  static constexpr size_t kBlockSlotBytes = 464;

  // The block of level `level` between columns i0..i0 + 1 and j0..j0 + 1
  // and samples m0..m0 + 1 (|i0|, |j0| < kMaxIndex - 2, 0 <= m0 <
  // kMaxSample, level 0..15), with the ring of columns around it
  // (ColumnBlock). Missing samples are traced with `trace(int64_t i,
  // int64_t j, int first, int count, const glm::dvec3& depth_first,
  // glm::dvec3* out) -> bool`: out[q] the optical depth at sample first +
  // 1 + q of column (i, j) (false: the frame failed; nothing is kept).
  // Null on failure; else valid until the next call.
  template <class Trace>
  const ColumnBlock* Block(int level, int64_t i0, int64_t j0, int m0, Trace&& trace) {
    const LatticePoint key{int32_t(i0), int32_t(j0), int32_t(m0), level};
    const size_t hash = LatticePointHash(key);
    if (!keys_.empty()) {
      const size_t at = hash & (keys_.size() - 1);
      if (keys_[at] == key) return &blocks_[at];
    }
    // (the table grows with the samples kept, so a cache that serves a few
    // rays stays small; eightfold, so that a frame's few tables before the
    // largest cost little)
    const size_t want = std::clamp<size_t>(std::bit_ceil(samples_ / 16 + 1), 16, kMaxBlocks);
    if (keys_.size() < want) GrowBlocks(std::min(kMaxBlocks, std::max(want, 8 * keys_.size())));
    const size_t at = hash & (keys_.size() - 1);
    keys_[at] = kNoBlock;
    ColumnBlock& b = blocks_[at];
    // The block's own four columns first, then, where they may be
    // interpolated and are not all alike (above the fog, in its shadow),
    // the eight beside them.
    auto column = [&](int64_t i, int64_t j) -> const glm::dvec3* {  // (samples m0, m0 + 1)
      const glm::dvec3* d = Samples(level, i, j, m0 + 1, [&](int first, int count, const glm::dvec3& depth,
                                                             glm::dvec3* out) {
        return trace(i, j, first, count, depth, out);
      });
      return d == nullptr ? nullptr : d + m0;
    };
    glm::dvec3 corner[8];
    for (int c = 0; c < 4; ++c) {
      const glm::dvec3* d = column(i0 + (c & 1), j0 + (c >> 1));
      if (d == nullptr) return nullptr;
      corner[c] = -d[0];
      corner[c + 4] = -d[1];
    }
    LatticeBlock corners;
    corners.Set(corner);
    b.shape = corners.shape;
    for (int k = 0; k < 3; ++k) b.dark[k] = corners.dark[k];
    bool alike = true;
    for (int c = 1; c < 8; ++c) alike = alike && corner[c] == corner[0];
    b.curved = b.shape != LatticeBlock::kSteep && !alike;
    // (one channel for three where the block is grey; the columns beside it
    // must be too)
    const bool grey = b.shape == LatticeBlock::kGrey;
    const int channels = grey ? 1 : 3;
    for (int k = 0; k < channels; ++k) {
      ColumnBlock::Channel& ch = b.ch[k];
      ch.lo = ch.hi = corner[0][k];
      for (int c = 0; c < 8; ++c) {
        ch.log_light[c] = corner[c][k];
        ch.lo = std::min(ch.lo, corner[c][k]);
        ch.hi = std::max(ch.hi, corner[c][k]);
      }
    }
    // Column r of side 0 or 1 across axis a (0: u, 1: v): the one beside
    // the block's corner column r (along the other axis) on that side.
    for (int q = 0; q < 8 && b.curved; ++q) {
      const int r = q & 1, side = (q >> 1) & 1, axis = q >> 2;
      const int64_t i = axis == 0 ? (side == 0 ? i0 - 1 : i0 + 2) : i0 + r;
      const int64_t j = axis == 0 ? j0 + r : (side == 0 ? j0 - 1 : j0 + 2);
      const glm::dvec3* d = column(i, j);
      if (d == nullptr) return nullptr;
      if (grey && !(d[0].x == d[0].y && d[0].x == d[0].z && d[1].x == d[1].y && d[1].x == d[1].z)) {
        b.curved = false;
        break;
      }
      // The edge's curvature: the mean of its two second differences,
      // (beside_0 - near_0 + beside_1 - near_1) / 2, near_s the block's
      // corner column next to beside_s.
      const int near = axis == 0 ? 2 * r + side : r + 2 * side;
      for (int k = 0; k < channels; ++k) {
        ColumnBlock::Channel& ch = b.ch[k];
        for (int m = 0; m < 2; ++m) {
          const double beside = -d[m][k];
          ch.lo = std::min(ch.lo, beside);
          ch.hi = std::max(ch.hi, beside);
          const double share = 0.5 * (beside - corner[near + 4 * m][k]);
          double& curve = axis == 0 ? ch.curve_u[r + 2 * m] : ch.curve_v[r + 2 * m];
          curve = side == 0 ? share : curve + share;
        }
        b.curved = b.curved && ch.hi - ch.lo <= kMaxLatticeLogRatio;
      }
    }
    keys_[at] = key;
    return &b;
  }

  // Samples 0..last of column (level, i, j), tracing missing chunks with
  // `trace(int first, int count, const glm::dvec3& depth_first, glm::dvec3*
  // out) -> bool` (as Block's, for this column). Null on failure; else
  // valid until the next call.
  template <class Trace>
  const glm::dvec3* Samples(int level, int64_t i, int64_t j, int last, Trace&& trace) {
    const uint64_t key = uint64_t(level) << 60 | (uint64_t(i) & kIndexMask) << 30 |
                         (uint64_t(j) & kIndexMask);
    ColumnSlot* slot = columns_.empty() ? nullptr : FindColumn(key);
    if (slot != nullptr && int(slot->samples.size()) > last) return slot->samples.data();
    const size_t chunks = size_t(last + kChunk - 1) / kChunk;  // samples 1..last
    const size_t want = chunks * kChunk + 1;
    if (samples_ + want > kMaxSamples) {
      columns_.assign(columns_.size(), ColumnSlot{});
      column_count_ = samples_ = 0;
      slot = columns_.empty() ? nullptr : FindColumn(key);
    }
    if (slot == nullptr || slot->samples.empty()) {
      if (2 * (column_count_ + 1) > columns_.size()) GrowColumns();
      slot = FindColumn(key);
      slot->key = key;
      slot->samples.assign(1, glm::dvec3(0.0));
      ++column_count_;
    }
    std::vector<glm::dvec3>& col = slot->samples;
    const size_t had = col.size();
    col.resize(want);
    for (size_t first = had - 1; first + 1 < want; first += kChunk) {
      if (!trace(int(first), kChunk, col[first], &col[first + 1])) {
        col.resize(had);
        return nullptr;
      }
    }
    samples_ += want - had;
    return col.data();
  }

 private:
  static constexpr uint64_t kIndexMask = (uint64_t(1) << 30) - 1;
  static constexpr LatticePoint kNoBlock{0, 0, 0, -1};  // (level -1: an empty slot)
  static_assert(sizeof(LatticePoint) + sizeof(ColumnBlock) <= kBlockSlotBytes);
  // The block table at n slots (a power of two), keeping the blocks built:
  // the new slots' bytes are not written until a block is built in them,
  // so pages the table never uses are never touched.
  void GrowBlocks(size_t n) {
    std::vector<LatticePoint> keys(n, kNoBlock);
    std::unique_ptr<ColumnBlock[]> blocks = std::make_unique_for_overwrite<ColumnBlock[]>(n);
    for (size_t i = 0; i < keys_.size(); ++i)
      if (!(keys_[i] == kNoBlock)) {
        const size_t at = LatticePointHash(keys_[i]) & (n - 1);
        keys[at] = keys_[i];
        std::memcpy(&blocks[at], &blocks_[i], sizeof(ColumnBlock));  // (channels a grey block leaves unset too)
      }
    keys_.swap(keys);
    blocks_ = std::move(blocks);
  }
  // A column's samples (none: the slot is free), in an open-addressed
  // table at most half full (linear probing).
  struct ColumnSlot {
    uint64_t key = 0;
    std::vector<glm::dvec3> samples;
  };
  ColumnSlot* FindColumn(uint64_t key) {
    const size_t mask = columns_.size() - 1;
    uint64_t h = key * 0x9E3779B97F4A7C15ull;
    for (size_t k = size_t(h ^ (h >> 29)) & mask;; k = (k + 1) & mask)
      if (columns_[k].samples.empty() || columns_[k].key == key) return &columns_[k];
  }
  void GrowColumns() {
    std::vector<ColumnSlot> old(std::max<size_t>(64, 2 * columns_.size()));
    old.swap(columns_);
    for (ColumnSlot& o : old)
      if (!o.samples.empty()) *FindColumn(o.key) = std::move(o);
  }
  std::vector<ColumnSlot> columns_;  // a power of two of them (or none yet)
  size_t column_count_ = 0, samples_ = 0;
  std::vector<LatticePoint> keys_;          // a power of two of them (or none yet)
  std::unique_ptr<ColumnBlock[]> blocks_;  // block i belongs to keys_[i]
};

class FogLightCache {
 public:
  // Points kept at most; the cache starts again when full (its values do not
  // depend on what it held, so nothing but time changes).
  static constexpr size_t kMaxPoints = size_t(1) << 16;
  // Blocks whose eight values are kept together, at most (a direct-mapped
  // table beside the points': neighbouring pixels ask for the same blocks,
  // one lookup instead of eight).
  static constexpr size_t kMaxBlocks = size_t(1) << 12;
  // Bytes it holds at most (the points' open-addressed slots, at most half
  // of them used, the blocks', and the columns': 24 bytes a sample, at
  // least a chunk's worth of samples per column and its table slot).
  static constexpr size_t kMaxBytes = 2 * kMaxPoints * 48 + kMaxBlocks * 224 +
                                      FogColumnCache::kMaxSamples * 32 +
                                      FogColumnCache::kMaxBlocks * FogColumnCache::kBlockSlotBytes;

  void Clear() {
    slots_.assign(slots_.size(), Slot{});
    used_ = 0;
  }

  // The light-space lattice, under one directional light.
  FogColumnCache columns;

  // The block of level `level` whose lowest corner is lattice point `i0`:
  // the log-light (per channel; -inf where no light arrives) at its eight
  // points, computing missing ones with `light(const glm::dvec3& p_grid,
  // glm::dvec3* log_light) -> bool` (false: the frame failed; nothing is
  // kept). Null on failure; else valid until the next call.
  template <class Light>
  const LatticeBlock* Block(int level, const glm::i64vec3& i0, Light&& light) {
    constexpr int64_t kFar = int64_t(1) << 30;  // (lattice indices of any grid fit)
    const bool keep = std::abs(i0.x) < kFar && std::abs(i0.y) < kFar && std::abs(i0.z) < kFar;
    const LatticePoint b{int32_t(i0.x), int32_t(i0.y), int32_t(i0.z), level};
    BlockSlot* block = &far_;
    if (keep) {
      // (the table grows with the points kept, so a cache that serves one
      // ray stays small)
      const size_t want = std::clamp<size_t>(std::bit_ceil(used_ / 4 + 1), 16, kMaxBlocks);
      if (blocks_.size() < want) blocks_.assign(want, BlockSlot{});
      block = &blocks_[LatticePointHash(b) & (blocks_.size() - 1)];
      if (block->key == b) return &block->block;
    }
    if (used_ + 8 > kMaxPoints) Clear();
    const double s = vox::Pow2(level);
    glm::dvec3 out[8];
    for (int c = 0; c < 8; ++c) {
      const glm::i64vec3 i(i0.x + (c & 1), i0.y + ((c >> 1) & 1), i0.z + ((c >> 2) & 1));
      const glm::dvec3 q = (glm::dvec3(i) + 0.5) * s + kLatticeOffset;
      if (!keep) {
        if (!light(q, &out[c])) return nullptr;
        continue;
      }
      if (2 * (used_ + 1) > slots_.size()) Grow();
      const LatticePoint p{int32_t(i.x), int32_t(i.y), int32_t(i.z), level};
      Slot* slot = Find(p);
      if (!slot->used) {
        if (!light(q, &slot->value)) return nullptr;
        slot->key = p;
        slot->used = true;
        ++used_;
      }
      out[c] = slot->value;
    }
    block->block.Set(out);
    block->key = b;
    return &block->block;
  }

 private:
  struct Slot {
    LatticePoint key{0, 0, 0, 0};
    glm::dvec3 value{0.0};
    bool used = false;
  };
  // p's slot, or the free slot where it belongs (linear probing; the table
  // is at most half full).
  Slot* Find(const LatticePoint& p) {
    const size_t mask = slots_.size() - 1;
    for (size_t k = LatticePointHash(p) & mask;; k = (k + 1) & mask)
      if (!slots_[k].used || slots_[k].key == p) return &slots_[k];
  }
  void Grow() {
    std::vector<Slot> old(std::max<size_t>(64, 2 * slots_.size()));
    old.swap(slots_);
    for (const Slot& o : old)
      if (o.used) *Find(o.key) = o;
  }

  struct BlockSlot {
    LatticePoint key{0, 0, 0, -1};  // the block's lowest corner (level -1: empty)
    LatticeBlock block;
  };
  static_assert(sizeof(BlockSlot) <= 224);

  std::vector<Slot> slots_;  // a power of two of them (or none yet)
  size_t used_ = 0;
  std::vector<BlockSlot> blocks_;  // a power of two of them (or none yet)
  BlockSlot far_;                  // a block too far to keep: its last answer
};

}  // namespace vox::render_internal

#endif  // VOX_RENDER_INTERNAL_FOG_LIGHT_H_
