// LodPyramid: a store's level-of-detail pyramid opened and checked
// against it. The pyramid is built by storage/lod_build.cpp (BuildLod) and
// storage/lod_stream.cpp (LodStream), from the reducers of
// storage/internal/lod_reduce.h through the writers of
// storage/internal/lod_write.h.
#include "storage/lod.h"

#include <algorithm>
#include <filesystem>

#include "storage/internal/format.h"

namespace vox {

namespace fs = std::filesystem;
using storage_internal::kLodDirName;

int LodMaxLevel(int base_levels) { return base_levels >= 3 ? base_levels - 2 : 0; }

int LodBrickDepth(int base_levels, int base_brick_depth, int level) {
  const int levels = base_levels - level;
  return std::max(1, std::min(base_brick_depth, levels - 1));
}

bool HasLod(const std::string& store_dir) {
  std::error_code ec;
  return fs::is_directory(fs::path(store_dir) / kLodDirName, ec);
}

StatusOr<std::unique_ptr<LodPyramid>> LodPyramid::Open(const std::string& store_dir, Store& base,
                                                       const OpenOptions& options) {
  const fs::path dir = fs::path(store_dir) / kLodDirName;
  if (!HasLod(store_dir))
    return NotFoundError("store '" + store_dir +
                         "' has no level-of-detail pyramid (lod/): re-ingest it with vox-ingest, "
                         "or add one with `vox-ingest --add-lod " + store_dir + "`");
  const StoreMeta& bm = base.meta();
  auto p = std::unique_ptr<LodPyramid>(new LodPyramid());
  p->base_bricks_ = bm.brick_count;
  for (int l = 1; l <= LodMaxLevel(bm.levels); ++l) {
    const std::string ldir = (dir / std::to_string(l)).string();
    VOX_ASSIGN_OR_RETURN(auto s, Store::Open(ldir, options));
    const StoreMeta& m = s->meta();
    if (m.lod_level != l || m.lod_base_store_id != base.store_id() ||
        m.lod_base_levels != bm.levels)
      return InvalidArgumentError(
          "'" + ldir + "' is not level " + std::to_string(l) + " of store '" + store_dir +
          "' (it belongs to another store: re-build the pyramid with `vox-ingest --add-lod " +
          store_dir + " --force`)");
    if (m.levels != bm.levels - l || m.grid_class != bm.grid_class || !m.has_coverage)
      return InvalidArgumentError("'" + ldir + "' does not fit store '" + store_dir +
                                  "' (levels, grid class or coverage)");
    p->levels_.push_back(std::move(s));
  }
  return p;
}

std::vector<uint64_t> LodPyramid::brick_counts() const {
  std::vector<uint64_t> n{base_bricks_};
  for (const auto& s : levels_) n.push_back(s->meta().brick_count);
  return n;
}

}  // namespace vox
