// Generate(): procedural shape -> vox store, brick by brick (tools/gen/generate.h).
#include "tools/gen/generate.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <mutex>
#include <new>
#include <thread>
#include <vector>

#include "core/util/parallel.h"
#include "ingest/placement.h"
#include "storage/lod.h"
#include "tools/gen/shapes.h"

namespace vox::gen {
namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string FormatDouble(double v) {
  char buf[64];
  snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

int Log2Exact(uint64_t v) {
  int n = 0;
  while ((uint64_t(1) << n) < v) ++n;
  return n;
}

// FNV-1a: the store id from the canonical options (never 0: 0 asks for a
// random id).
uint64_t HashId(const std::string& s) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char ch : s) {
    h ^= ch;
    h *= 0x100000001b3ull;
  }
  return h == 0 ? 1 : h;
}

// Depth-first enumeration of the brick-level octants the shape may occupy,
// in Morton order (children in digit order x | y << 1 | z << 2). The stack
// holds at most 8 nodes per level.
class BrickEnumerator {
 public:
  BrickEnumerator(const Shape& shape, int levels, int brick_level, double band)
      : shape_(shape), levels_(levels), brick_level_(brick_level), band_(band),
        half_(double(uint64_t(1) << (levels - 1))) {
    stack_.push_back({glm::u64vec3(0), 0});
  }

  // The next candidate brick, or false when there are no more.
  bool Next(glm::u64vec3* brick) {
    while (!stack_.empty()) {
      Node n = stack_.back();
      stack_.pop_back();
      const uint64_t s = uint64_t(1) << (levels_ - n.level);
      glm::dvec3 lo = glm::dvec3(n.c * s) - half_;
      if (!shape_.MayOccupy(lo, lo + double(s - 1), band_)) {
        covered_ += uint64_t(1) << (3 * (brick_level_ - n.level));
        continue;
      }
      if (n.level == brick_level_) {
        ++covered_;
        *brick = n.c;
        return true;
      }
      for (int d = 7; d >= 0; --d)  // popped in digit order
        stack_.push_back({n.c * uint64_t(2) + glm::u64vec3(d & 1, (d >> 1) & 1, (d >> 2) & 1),
                          n.level + 1});
    }
    return false;
  }

  // The grid's volume decided so far (enumerated or skipped), in bricks, of
  // Total(): the generation's progress.
  uint64_t Covered() const { return covered_; }
  uint64_t Total() const { return uint64_t(1) << (3 * brick_level_); }

 private:
  struct Node {
    glm::u64vec3 c;
    int level;
  };
  const Shape& shape_;
  const int levels_, brick_level_;
  const double band_, half_;
  std::vector<Node> stack_;
  uint64_t covered_ = 0;
};

// Fills one brick's occupied voxels in Morton order: descends through the
// octants the shape may occupy and tests every voxel of blocks of 4^3.
class BrickFiller {
 public:
  BrickFiller(const Shape& shape, int levels, int depth, double band)
      : shape_(shape), depth_(depth), band_(band), half_(double(uint64_t(1) << (levels - 1))) {}

  std::vector<BrickVoxel> Fill(const glm::u64vec3& brick) const {
    std::vector<BrickVoxel> out;
    Descend(glm::dvec3(brick << uint64_t(depth_)) - half_, glm::u64vec3(0), depth_, &out);
    return out;
  }

 private:
  // `base`: the index point of the brick's voxel (0,0,0); `o`, `k`: the
  // block of 2^k voxels at brick-local `o`.
  void Descend(const glm::dvec3& base, const glm::u64vec3& o, int k,
               std::vector<BrickVoxel>* out) const {
    const uint64_t s = uint64_t(1) << k;
    glm::dvec3 lo = base + glm::dvec3(o);
    if (!shape_.MayOccupy(lo, lo + double(s - 1), band_)) return;
    if (k <= 2) {
      for (uint64_t m = 0; m < s * s * s; ++m) {
        glm::u64vec3 l(0);
        for (int j = 0; j < k; ++j) {
          uint64_t digit = (m >> (3 * j)) & 7;
          l.x |= (digit & 1) << j;
          l.y |= ((digit >> 1) & 1) << j;
          l.z |= ((digit >> 2) & 1) << j;
        }
        glm::u64vec3 v = o + l;
        BrickVoxel bv;
        if (shape_.Voxel(base + glm::dvec3(v), band_, &bv.attr)) {
          bv.x = uint32_t(v.x);
          bv.y = uint32_t(v.y);
          bv.z = uint32_t(v.z);
          out->push_back(bv);
        }
      }
      return;
    }
    const uint64_t h = s / 2;
    for (int d = 0; d < 8; ++d)
      Descend(base, o + glm::u64vec3(d & 1, (d >> 1) & 1, (d >> 2) & 1) * h, k - 1, out);
  }

  const Shape& shape_;
  const int depth_;
  const double band_, half_;
};

// Whether a grid voxel is in the store: the tests BrickEnumerator and
// BrickFiller make of the blocks holding it (from the root down to the
// filler's 4^3 blocks, or to the brick when it is smaller), then the band's.
// The same arithmetic on the same (integral) coordinates, so the same answer.
class StoreOccupancy {
 public:
  StoreOccupancy(const Shape& shape, int levels, int brick_level, double band)
      : shape_(shape), levels_(levels), last_(std::max(brick_level, levels - 2)), band_(band),
        half_(double(uint64_t(1) << (levels - 1))) {}

  bool operator()(const glm::u64vec3& g) const {
    for (int level = 0; level <= last_; ++level) {
      const int k = levels_ - level;  // the block's side is 2^k
      const uint64_t s = uint64_t(1) << k;
      const glm::dvec3 lo = glm::dvec3((g >> uint64_t(k)) * s) - half_;
      if (!shape_.MayOccupy(lo, lo + double(s - 1), band_)) return false;
    }
    return shape_.Voxel(glm::dvec3(g) - half_, band_, nullptr);
  }

 private:
  const Shape& shape_;
  const int levels_, last_;
  const double band_, half_;
};

}  // namespace

StatusOr<Levels> ChooseLevels(std::string_view text, int n) {
  Levels l;
  // The syntax and the limits are vox-ingest's (ingest/placement.h).
  VOX_ASSIGN_OR_RETURN(const LevelsChoice choice, ParseLevels(text, /*min_brick_depth=*/0));
  if (choice.automatic) {
    l.brick_depth = std::min(5, n - 1);
    l.brick_level = n - l.brick_depth;
    return l;
  }
  l.brick_level = choice.brick_level;
  l.brick_depth = choice.brick_depth;
  auto bad = [&](const std::string& why) {
    return InvalidArgumentError("--levels " + std::string(text) + ": " + why);
  };
  if (l.brick_depth > kMaxBrickDepth)
    return bad("bricks of more than " + std::to_string(kMaxBrickDepth) +
               " levels would not keep memory bounded");
  if (l.brick_level + l.brick_depth != n)
    return bad("N1 + N2 must equal log2(--size) = " + std::to_string(n));
  return l;
}

Status ValidateOptions(const GenerateOptions& o) {
  if (o.shape.empty()) return InvalidArgumentError("no shape given");
  if (o.size < 2 || o.size > (uint64_t(1) << kMaxSizeLog2) || (o.size & (o.size - 1)) != 0)
    return InvalidArgumentError("--size " + std::to_string(o.size) +
                                ": must be a power of two from 2 to 2^" +
                                std::to_string(kMaxSizeLog2) + " (1048576)");
  VOX_RETURN_IF_ERROR(MakeShape(o.shape, o.size).status());  // the name, and whether the size suits it
  VOX_RETURN_IF_ERROR(ChooseLevels(o.levels, Log2Exact(o.size)).status());
  if (!(o.band > 0) || !(o.band <= double(o.size)))
    return InvalidArgumentError("--band " + FormatDouble(o.band) +
                                ": must be greater than 0 and at most --size voxels");
  if (o.threads < 0) return InvalidArgumentError("--threads must be >= 1 (or 0 for all cores)");
  if (o.zstd_level < 1 || o.zstd_level > 22)
    return InvalidArgumentError("--zstd-level " + std::to_string(o.zstd_level) +
                                ": must be in 1..22");
  if (o.normal_bits < 8 || o.normal_bits > 16)
    return InvalidArgumentError("--normal-bits " + std::to_string(o.normal_bits) +
                                ": must be in 8..16");
  if (o.output.empty()) return InvalidArgumentError("no output store directory given");
  return OkStatus();
}

std::string CanonicalOptions(const GenerateOptions& o) {
  std::string levels = o.levels;
  if (auto l = ChooseLevels(o.levels, Log2Exact(o.size)); l.ok())
    levels = std::to_string(l->brick_level) + "+" + std::to_string(l->brick_depth);
  return "vox-gen " + o.shape + " --size " + std::to_string(o.size) + " --levels " + levels +
         " --band " + FormatDouble(o.band) + " --zstd-level " + std::to_string(o.zstd_level) +
         " --normal-bits " + std::to_string(o.normal_bits);
}

namespace {

// The store's meta for the shape: a level set (or a fog volume for a field)
// of 2^n voxels per axis centred on index 0, before its counts are known.
StoreMeta ShapeMeta(const GenerateOptions& o, const Shape& shape, int n, const Levels& lv) {
  StoreMeta meta;
  meta.source_file = "vox-gen:" + o.shape;
  meta.grid_name = o.shape;
  meta.grid_class = shape.IsField() ? GridClass::kFogVolume : GridClass::kLevelSet;
  meta.levels = n;
  meta.brick_level = lv.brick_level;
  meta.origin = glm::i64vec3(-int64_t(o.size / 2));
  const double vs = VoxelSize(o.size);
  meta.index_to_world = glm::dmat4(vs);
  meta.index_to_world[3][3] = 1.0;
  meta.voxel_size = vs;
  meta.has_normal = !shape.IsField();
  meta.has_density = shape.IsField();
  meta.has_color = shape.HasColor();
  meta.isovalue = 0.0;
  meta.threshold = 0.0;  // fields: occupied where the density exceeds 0
  meta.build_options = CanonicalOptions(o);
  return meta;
}

}  // namespace

StatusOr<GenerateStats> Generate(const GenerateOptions& o, const GenerateProgress& progress) {
  const double t0 = Now();
  VOX_RETURN_IF_ERROR(ValidateOptions(o));
  const int n = Log2Exact(o.size);
  VOX_ASSIGN_OR_RETURN(Levels lv, ChooseLevels(o.levels, n));
  VOX_ASSIGN_OR_RETURN(std::unique_ptr<Shape> shape, MakeShape(o.shape, o.size));

  GenerateStats stats;
  StoreMeta& meta = stats.meta;
  meta = ShapeMeta(o, *shape, n, lv);

  WriteOptions wo;
  wo.zstd_level = o.zstd_level;
  wo.normal_bits = o.normal_bits;
  wo.force = o.force;
  wo.store_id = HashId(meta.build_options);
  // The pyramid is built with the bricks (LodStream) in the store's
  // temporary directory and published with it (deterministic: its ids
  // derive from the store's).
  LodBuildOptions lo;
  lo.zstd_level = o.zstd_level;
  lo.normal_bits = o.normal_bits;
  lo.threads = o.threads;
  lo.cancel = o.cancel;
  std::unique_ptr<LodStream> lod;
  if (o.lod) {
    wo.before_publish = [&lod, &stats](const std::string& temp_dir) -> Status {
      const double t = Now();
      VOX_ASSIGN_OR_RETURN(LodBuildStats ls, lod->Finish(temp_dir));
      stats.lod_levels = ls.levels;
      stats.seconds_lod = Now() - t;
      return OkStatus();
    };
  }
  // What an interrupted run keeps: nothing new. The writer builds in a
  // temporary directory (removed when it is destroyed) and replaces what
  // is at the target only when the store is complete.
  std::error_code ec;
  const bool existed = std::filesystem::exists(o.output, ec);
  const Status interrupted =
      IoError(existed ? "interrupted; no store written: '" + o.output + "' is as it was before"
                      : "interrupted; no store written at '" + o.output + "', nothing left behind");
  VOX_ASSIGN_OR_RETURN(std::unique_ptr<StoreWriter> writer,
                       StoreWriter::Create(o.output, meta, wo));
  if (o.lod) {
    VOX_ASSIGN_OR_RETURN(lod, LodStream::Create(writer->temp_dir(), meta, wo, lo));
  }
  const StoreOccupancy occupancy(*shape, n, lv.brick_level, o.band);

  stats.threads = o.threads > 0 ? o.threads : int(std::max(1u, std::thread::hardware_concurrency()));
  BrickEnumerator bricks(*shape, n, lv.brick_level, o.band);
  const BrickFiller filler(*shape, n, lv.brick_depth, o.band);
  std::atomic<bool> failed{false};
  Status first_error;
  std::mutex error_mu;
  auto fail = [&](Status s) {
    std::lock_guard<std::mutex> lock(error_mu);
    if (first_error.ok()) first_error = std::move(s);
    failed.store(true);
  };
  struct Item {
    glm::u64vec3 brick{0};
    uint64_t covered = 0;  // the enumerator's Covered() after this brick
    std::vector<BrickVoxel> voxels;
    std::shared_ptr<LodReducedBrick> lod;  // its share of the pyramid
  };
  const double t1 = Now();
  RunPipeline<Item>(
      stats.threads, size_t(2 * stats.threads),
      [&](Item& it) {
        if (o.cancel != nullptr && o.cancel->load()) fail(interrupted);
        if (failed.load() || !bricks.Next(&it.brick)) return false;
        ++stats.candidate_bricks;
        it.covered = bricks.Covered();
        return true;
      },
      [&](Item& it) {
        if (failed.load()) return;
        try {
          it.voxels = filler.Fill(it.brick);
          if (lod && !it.voxels.empty()) {
            auto r = lod->Reduce(it.brick, it.voxels, occupancy);
            if (!r.ok()) fail(r.status());
            else it.lod = std::move(r).value();
          }
        } catch (const std::bad_alloc&) {
          fail(ResourceExhaustedError("out of memory while filling a brick"));
        }
      },
      // One brick at a time, in enumeration order: the brick file's layout
      // does not depend on thread timing.
      [&](Item& it) {
        if (failed.load()) return;
        if (!it.voxels.empty()) {
          const size_t count = it.voxels.size();
          Status s = writer->AddBrick(it.brick, std::move(it.voxels));
          if (s.ok() && lod) s = lod->Take(it.lod);
          if (!s.ok()) return fail(s);
          ++stats.bricks;
          stats.voxels += count;
        }
        if (progress && it.covered < bricks.Total())  // the last report follows the loop
          progress({it.covered, bricks.Total(), stats.bricks, stats.voxels});
      });
  if (progress && first_error.ok()) {
    progress({bricks.Total(), bricks.Total(), stats.bricks, stats.voxels});
  }
  // The writer's destructor removes its temporary directory. Interrupted,
  // whichever step noticed first (the pyramid's reduction polls the flag
  // too), the whole store is abandoned.
  if (!first_error.ok())
    return o.cancel != nullptr && o.cancel->load() ? interrupted : first_error;
  const double t2 = Now();
  if (Status s = writer->Finish(); !s.ok()) {
    // Interrupted while the index or the pyramid was written: the store as
    // a whole is abandoned, not only the pyramid.
    return o.cancel != nullptr && o.cancel->load() ? interrupted : s;
  }
  const double t3 = Now();
  meta.voxel_count = stats.voxels;
  meta.brick_count = stats.bricks;
  stats.seconds_bricks = t2 - t1;
  stats.seconds_finish = t3 - t2;
  stats.seconds_total = t3 - t0;
  return stats;
}

}  // namespace vox::gen
