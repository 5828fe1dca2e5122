// The level-of-detail pyramid (storage/lod.h): every coarse cell's
// aggregates against a brute-force computation from the voxels, pyramids of
// another store refused, stores without one, replacing a store with one.
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <map>
#include <random>
#include <set>
#include <thread>
#include <tuple>

#include <glm/geometric.hpp>

#include "storage/lod.h"
#include "storage/store_budget.h"
#include "tests/storage/test_util.h"

namespace vox::storage_test {
namespace {

namespace fs = std::filesystem;
using Key = std::tuple<uint64_t, uint64_t, uint64_t>;

// Clustered random voxels (a few dense blobs and scattered ones) in a 2^levels grid.
std::vector<LeafPoint> RandomVoxels(int levels, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const uint64_t n = uint64_t(1) << levels;
  std::map<Key, bool> set;
  std::uniform_int_distribution<uint64_t> any(0, n - 1);
  for (int i = 0; i < 600; ++i) set[{any(rng), any(rng), any(rng)}] = true;
  for (int b = 0; b < 4; ++b) {
    const uint64_t cx = any(rng), cy = any(rng), cz = any(rng);
    for (uint64_t z = 0; z < 9; ++z)
      for (uint64_t y = 0; y < 9; ++y)
        for (uint64_t x = 0; x < 9; ++x)
          if ((x + y + z + b) % 3 != 0 && cx + x < n && cy + y < n && cz + z < n)
            set[{cx + x, cy + y, cz + z}] = true;
  }
  std::vector<LeafPoint> out;
  for (const auto& [k, v] : set) out.push_back({std::get<0>(k), std::get<1>(k), std::get<2>(k)});
  return out;
}

struct Expected {
  uint64_t count = 0;
  glm::dvec3 normal{0.0}, surface{0.0}, color{0.0};
  double density = 0;
};

// Checks every cell of every level against the voxels, brute force.
void CheckPyramid(const std::string& dir, const std::vector<LeafPoint>& voxels,
                  const StoreMeta& meta) {
  OpenOptions oo;
  auto base = Store::Open(dir, oo);
  ASSERT_TRUE(base.ok()) << base.status().ToString();
  auto pyr = LodPyramid::Open(dir, **base, oo);
  ASSERT_TRUE(pyr.ok()) << pyr.status().ToString();
  ASSERT_EQ((*pyr)->max_level(), LodMaxLevel(meta.levels));
  // Level sets: each voxel's area-weighted contribution to its cells' normal
  // (storage/FORMAT.md): its stored normal / max |n_a| when the voxel next to
  // it outwards along that axis (the first of equal ones) is not occupied.
  std::set<Key> occupied;
  for (const LeafPoint& p : voxels) occupied.insert({p.x, p.y, p.z});
  std::map<Key, glm::dvec3> surface;
  const uint64_t n = uint64_t(1) << meta.levels;
  for (const LeafPoint& p : voxels) {
    if (!meta.has_normal) break;
    auto loc = Locate(**base, p.x, p.y, p.z);
    ASSERT_TRUE(loc.ok() && loc->has_value());
    auto a = (*base)->Attributes((*loc)->brick, (*loc)->payload);
    ASSERT_TRUE(a.ok());
    const glm::dvec3 nv(a->normal);
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (std::fabs(nv[k]) > std::fabs(nv[axis])) axis = k;
    if (nv[axis] == 0) continue;
    uint64_t c[3] = {p.x, p.y, p.z};
    if (nv[axis] > 0 ? c[axis] + 1 == n : c[axis] == 0) {
      surface[{p.x, p.y, p.z}] = nv / std::fabs(nv[axis]);  // the grid's edge: outside
      continue;
    }
    c[axis] = nv[axis] > 0 ? c[axis] + 1 : c[axis] - 1;
    if (!occupied.count({c[0], c[1], c[2]}))
      surface[{p.x, p.y, p.z}] = nv / std::fabs(nv[axis]);
  }
  for (int l = 1; l <= (*pyr)->max_level(); ++l) {
    SCOPED_TRACE("level " + std::to_string(l));
    std::map<Key, Expected> cells;
    for (const LeafPoint& p : voxels) {
      Expected& e = cells[{p.x >> l, p.y >> l, p.z >> l}];
      const VoxelAttributes a = AttrFor(p.x, p.y, p.z, meta);
      ++e.count;
      e.normal += glm::dvec3(a.normal);
      if (auto it = surface.find({p.x, p.y, p.z}); it != surface.end()) e.surface += it->second;
      e.color += glm::dvec3(a.color);
      e.density += meta.has_density ? a.density : 1.0;
    }
    Store& s = *(*pyr)->level(l);
    const StoreMeta& m = s.meta();
    EXPECT_EQ(m.levels, meta.levels - l);
    EXPECT_EQ(m.lod_level, l);
    EXPECT_EQ(m.lod_base_store_id, (*base)->store_id());
    EXPECT_TRUE(m.has_coverage);
    ASSERT_EQ(m.voxel_count, cells.size());  // no cell more, none less (all found below)
    const double cell_voxels = std::ldexp(1.0, 3 * l);
    for (const auto& [k, e] : cells) {
      auto loc = Locate(s, std::get<0>(k), std::get<1>(k), std::get<2>(k));
      ASSERT_TRUE(loc.ok()) << loc.status().ToString();
      ASSERT_TRUE(loc->has_value()) << "cell missing at level " << l;
      auto a = s.Attributes((*loc)->brick, (*loc)->payload);
      ASSERT_TRUE(a.ok());
      EXPECT_NEAR(a->coverage, double(e.count) / cell_voxels, 0.6 / 65535 + 1e-7);
      if (meta.has_normal) {
        const glm::dvec3& sum = glm::length(e.surface) > 0 ? e.surface : e.normal;
        const double len = glm::length(sum);
        if (len > 1e-3 * double(e.count)) {
          const glm::dvec3 want = sum / len;
          EXPECT_GT(glm::dot(glm::dvec3(a->normal), want), 1.0 - 1e-6)  // 0.08 degrees: two quantisations
              << "normal of a cell of " << e.count << " voxels";
        }
      }
      if (meta.has_color) {
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(a->color[c], e.color[c] / double(e.count), 2e-3);
      }
      if (meta.has_density || meta.grid_class == GridClass::kFogVolume) {
        EXPECT_NEAR(a->density, e.density / cell_voxels, 1e-6 * (1 + e.density / cell_voxels));
      }
    }
  }
}

TEST(Lod, AggregatesEqualBruteForceLevelSetWithColour) {
  TempDir tmp;
  const StoreMeta meta = MetaFor(7, 4, GridClass::kLevelSet, /*color=*/true);  // bricks of 8^3
  const auto voxels = RandomVoxels(7, 11);
  const std::string dir = tmp / "s";
  ASSERT_TRUE(WriteVoxels(dir, voxels, meta).ok());
  LodBuildOptions lo;
  auto st = BuildLod(dir, lo);
  ASSERT_TRUE(st.ok()) << st.status().ToString();
  EXPECT_EQ(st->levels, 5);
  CheckPyramid(dir, voxels, meta);
}

// The brick-local levels are reduced on worker threads and taken in brick
// order: any number of threads writes the same pyramid, byte for byte (the
// same check as the aggregates: one thread is the plain serial cascade),
// and a cancelled build leaves no pyramid.
TEST(Lod, TheThreadsChangeNoByteOfThePyramid) {
  TempDir tmp;
  const StoreMeta meta = MetaFor(7, 4, GridClass::kLevelSet, /*color=*/true);  // bricks of 8^3
  const auto voxels = RandomVoxels(7, 23);
  ASSERT_TRUE(WriteVoxels(tmp / "s", voxels, meta).ok());
  auto read = [&] {
    std::map<std::string, std::string> bytes;
    for (const auto& e : fs::recursive_directory_iterator(tmp / "s/lod"))
      if (e.is_regular_file())
        bytes[fs::relative(e.path(), tmp / "s").string()] = ReadFile(e.path());
    return bytes;
  };
  auto files = [&](int threads) {
    std::error_code ec;
    fs::remove_all(tmp / "s/lod", ec);
    LodBuildOptions lo;
    lo.threads = threads;
    auto st = BuildLod(tmp / "s", lo);
    EXPECT_TRUE(st.ok()) << st.status().ToString();
    if (st.ok()) {
      EXPECT_GT(st->base_bricks_read, 200u);  // many times the workers' window
    }
    return read();
  };
  const auto one = files(1);
  ASSERT_GE(one.size(), 2u * 5u);  // bricks and index of each of the 5 levels
  EXPECT_EQ(files(2), one);
  EXPECT_EQ(files(5), one);
  CheckPyramid(tmp / "s", voxels, meta);

  std::atomic<bool> cancel{false};
  LodBuildOptions lo;
  lo.threads = 3;
  lo.force = true;
  lo.cancel = &cancel;
  lo.progress = [&](uint64_t done, uint64_t) {
    if (done == 50) cancel = true;
  };
  auto st = BuildLod(tmp / "s", lo);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.status().message().find("interrupted"), std::string::npos) << st.status().ToString();
  EXPECT_EQ(read(), one);  // the old pyramid stays
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp / "s"), fs::directory_iterator()), 3)
      << "a temporary was left beside the store's files and lod/";
}

// The levels a frame cannot use (finer than `first_level`) get the minimum
// cache share; the others share the rest, never more than the budget's cache.
TEST(Lod, BudgetGivesUnusedLevelsOnlyTheMinimum) {
  TempDir tmp;
  const StoreMeta meta = MetaFor(7, 4, GridClass::kLevelSet, false);
  const std::string dir = tmp / "s";
  ASSERT_TRUE(WriteVoxels(dir, RandomVoxels(7, 11), meta).ok());
  ASSERT_TRUE(BuildLod(dir, LodBuildOptions{}).ok());
  OpenOptions oo;
  auto base = Store::Open(dir, oo);
  ASSERT_TRUE(base.ok());
  auto pyr = LodPyramid::Open(dir, **base, oo);
  ASSERT_TRUE(pyr.ok());
  std::vector<Store*> all{base->get()}, levels;
  for (int l = 1; l <= (*pyr)->max_level(); ++l) levels.push_back((*pyr)->level(l));
  all.insert(all.end(), levels.begin(), levels.end());
  BudgetInputs in;
  in.image_width = in.image_height = 64;
  in.threads = 1;
  const uint64_t total = uint64_t(256) << 20, min_share = uint64_t(4) << 20;
  std::vector<uint64_t> even;
  for (int first : {0, 2}) {
    SCOPED_TRACE("first level " + std::to_string(first));
    auto b = BudgetStores(base->get(), levels, total, in, first);
    ASSERT_TRUE(b.ok()) << b.status().ToString();
    uint64_t sum = 0;
    for (size_t i = 0; i < all.size(); ++i) {
      const uint64_t cap = all[i]->cache_stats().capacity;
      sum += cap;
      if (int(i) < first) {
        EXPECT_LE(cap, min_share) << "level " << i;
      } else {
        EXPECT_GT(cap, min_share) << "level " << i;
        if (first > 0) {
          EXPECT_GT(cap, even[i]) << "level " << i << " got no more";
        }
      }
      if (first == 0) even.push_back(cap);
    }
    EXPECT_LE(sum, b->brick_cache);
  }
}

TEST(Lod, AggregatesEqualBruteForceFog) {
  TempDir tmp;
  for (bool density : {true, false}) {
    StoreMeta meta = MetaFor(6, 2, GridClass::kFogVolume, false);  // deep bricks: levels share them
    meta.has_density = density;
    const auto voxels = RandomVoxels(6, 5);
    const std::string dir = tmp / (density ? "d" : "n");
    ASSERT_TRUE(WriteVoxels(dir, voxels, meta).ok());
    ASSERT_TRUE(BuildLod(dir, LodBuildOptions{}).ok());
    CheckPyramid(dir, voxels, meta);
  }
}

TEST(Lod, WriterHookPublishesThePyramidWithTheStore) {
  TempDir tmp;
  const StoreMeta meta = MetaFor(6, 3, GridClass::kLevelSet, false);
  const auto voxels = RandomVoxels(6, 3);
  WriteOptions wo;
  wo.before_publish = [](const std::string& temp) { return BuildLod(temp, {}).status(); };
  ASSERT_TRUE(WriteVoxels(tmp / "s", voxels, meta, wo).ok());
  CheckPyramid(tmp / "s", voxels, meta);
  // A failing hook leaves no store at all.
  wo.before_publish = [](const std::string&) { return IoError("injected"); };
  EXPECT_FALSE(WriteVoxels(tmp / "t", voxels, meta, wo).ok());
  EXPECT_FALSE(fs::exists(tmp / "t"));
  // --force replaces a store that has a pyramid (and the new one has none).
  wo.before_publish = nullptr;
  wo.force = true;
  ASSERT_TRUE(WriteVoxels(tmp / "s", voxels, meta, wo).ok());
  EXPECT_FALSE(HasLod(tmp / "s"));
}

// The files of `dir`/lod, by path relative to `dir`.
std::map<std::string, std::string> LodFiles(const std::string& dir) {
  std::map<std::string, std::string> bytes;
  for (const auto& e : fs::recursive_directory_iterator(fs::path(dir) / "lod"))
    if (e.is_regular_file()) bytes[fs::relative(e.path(), dir).string()] = ReadFile(e.path());
  return bytes;
}

// Whether two sets of files are the same, naming those that differ.
::testing::AssertionResult SameFiles(const std::map<std::string, std::string>& a,
                                     const std::map<std::string, std::string>& b) {
  std::string diff;
  for (const auto& [name, bytes] : a) {
    auto it = b.find(name);
    if (it == b.end()) diff += " " + name + " (only in the first)";
    else if (it->second != bytes) diff += " " + name;
  }
  for (const auto& [name, bytes] : b)
    if (!a.count(name)) diff += " " + name + " (only in the second)";
  if (diff.empty()) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "files differ:" << diff;
}

// Writes `voxels` as a store whose pyramid a LodStream builds with its bricks
// (bricks in Morton order, each brick's voxels shuffled, reduced on several
// threads), as vox-ingest and vox-gen do.
Status WriteWithStream(const std::string& dir, const std::vector<LeafPoint>& voxels,
                       const StoreMeta& meta, LodBuildOptions lo = {}) {
  const int sub = meta.levels - meta.brick_level;
  const uint64_t lm = (uint64_t(1) << sub) - 1;
  std::set<Key> occupied;
  std::map<uint64_t, std::pair<glm::u64vec3, std::vector<BrickVoxel>>> bricks;  // Morton order
  for (const LeafPoint& p : voxels) {
    occupied.insert({p.x, p.y, p.z});
    const glm::u64vec3 b(p.x >> sub, p.y >> sub, p.z >> sub);
    BrickVoxel v;
    v.x = uint32_t(p.x & lm);
    v.y = uint32_t(p.y & lm);
    v.z = uint32_t(p.z & lm);
    v.attr = AttrFor(p.x, p.y, p.z, meta);
    auto& e = bricks[MortonKey(b)];
    e.first = b;
    e.second.push_back(v);
  }
  WriteOptions wo;
  wo.store_id = 0x5eed;
  std::unique_ptr<LodStream> stream;
  wo.before_publish = [&](const std::string& temp) { return stream->Finish(temp).status(); };
  VOX_ASSIGN_OR_RETURN(auto w, StoreWriter::Create(dir, meta, wo));
  VOX_ASSIGN_OR_RETURN(stream, LodStream::Create(w->temp_dir(), meta, wo, lo));
  auto occ = [&](const glm::u64vec3& g) { return occupied.count({g.x, g.y, g.z}) > 0; };
  std::mt19937_64 rng(7);
  std::vector<std::pair<glm::u64vec3, std::vector<BrickVoxel>>> list;
  for (auto& [k, b] : bricks) {
    std::shuffle(b.second.begin(), b.second.end(), rng);
    list.push_back(std::move(b));
  }
  // Reduced by 3 threads in turn, taken in order.
  std::vector<std::shared_ptr<LodReducedBrick>> reduced(list.size());
  std::vector<Status> errors(3);
  std::vector<std::thread> threads;
  for (size_t t = 0; t < 3; ++t)
    threads.emplace_back([&, t] {
      for (size_t i = t; i < list.size(); i += 3) {
        auto r = stream->Reduce(list[i].first, list[i].second, occ);
        if (!r.ok()) errors[t] = r.status();
        else reduced[i] = *r;
      }
    });
  for (std::thread& t : threads) t.join();
  for (const Status& e : errors) VOX_RETURN_IF_ERROR(e);
  for (size_t i = 0; i < list.size(); ++i) {
    VOX_RETURN_IF_ERROR(w->AddBrick(list[i].first, std::move(list[i].second)));
    VOX_RETURN_IF_ERROR(stream->Take(reduced[i]));
  }
  return w->Finish();
}

// The pyramid built with the store's bricks is, byte for byte, BuildLod's of
// the finished store: level sets (with and without colour) and fog volumes
// (with and without densities), bricks of 1 voxel (the top alone), 2^1,
// 2^3 and 2^8 (past the occupancy bitmap) voxels a side.
TEST(Lod, TheStreamBuildsBuildLodsPyramidByteForByte) {
  TempDir tmp;
  struct Case {
    int levels, brick_level;
    GridClass gc;
    bool color, density;
  };
  const Case cases[] = {{7, 4, GridClass::kLevelSet, true, false},
                        {7, 4, GridClass::kLevelSet, false, false},
                        {6, 5, GridClass::kLevelSet, false, false},
                        {5, 5, GridClass::kLevelSet, true, false},
                        {9, 1, GridClass::kLevelSet, false, false},
                        {7, 4, GridClass::kFogVolume, false, true},
                        {7, 3, GridClass::kFogVolume, true, false}};
  int n = 0;
  for (const Case& c : cases) {
    SCOPED_TRACE("case " + std::to_string(n));
    StoreMeta meta = MetaFor(c.levels, c.brick_level, c.gc, c.color);
    meta.has_density = c.density;
    const auto voxels = RandomVoxels(c.levels, 40 + uint64_t(n));
    const std::string dir = tmp / ("s" + std::to_string(n++));
    LodBuildOptions lo;
    lo.normal_bits = 12;
    ASSERT_TRUE(WriteWithStream(dir, voxels, meta, lo).ok());
    const auto streamed = LodFiles(dir);
    ASSERT_GE(streamed.size(), 2u * size_t(LodMaxLevel(c.levels)));
    lo.force = true;
    auto st = BuildLod(dir, lo);
    ASSERT_TRUE(st.ok()) << st.status().ToString();
    EXPECT_TRUE(SameFiles(LodFiles(dir), streamed));
    // (Cells of more than 2^16 voxels have coverages the check cannot tell apart.)
    if (LodMaxLevel(c.levels) <= 5) CheckPyramid(dir, voxels, meta);
  }
}

// A stream refuses bricks out of order, and one not finished leaves nothing.
TEST(Lod, TheStreamRefusesBricksOutOfOrderAndCleansUp) {
  TempDir tmp;
  const StoreMeta meta = MetaFor(6, 3, GridClass::kLevelSet, false);
  WriteOptions wo;
  wo.store_id = 9;
  auto w = StoreWriter::Create(tmp / "s", meta, wo);
  ASSERT_TRUE(w.ok());
  auto stream = LodStream::Create((*w)->temp_dir(), meta, wo, {});
  ASSERT_TRUE(stream.ok()) << stream.status().ToString();
  auto none = [](const glm::u64vec3&) { return false; };
  std::vector<BrickVoxel> one(1);
  auto a = (*stream)->Reduce(glm::u64vec3(1, 0, 0), one, none);
  auto b = (*stream)->Reduce(glm::u64vec3(0, 1, 0), one, none);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_TRUE((*stream)->Take(*b).ok());
  EXPECT_EQ((*stream)->Take(*a).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*stream)->Reduce(glm::u64vec3(0), {}, none).status().code(),
            StatusCode::kInvalidArgument);
  const std::string temp = (*w)->temp_dir();
  EXPECT_EQ(std::distance(fs::directory_iterator(temp), fs::directory_iterator()), 2)
      << "the brick file and the pyramid's temporary";
  stream->reset();
  EXPECT_EQ(std::distance(fs::directory_iterator(temp), fs::directory_iterator()), 1);
  // Without an id the pyramid cannot name its store.
  wo.store_id = 0;
  EXPECT_FALSE(LodStream::Create(temp, meta, wo, {}).ok());
}

TEST(Lod, PyramidOfAnotherStoreIsRefused) {
  TempDir tmp;
  const StoreMeta meta = MetaFor(6, 3, GridClass::kLevelSet, false);
  const auto voxels = RandomVoxels(6, 7);
  ASSERT_TRUE(WriteVoxels(tmp / "a", voxels, meta).ok());
  ASSERT_TRUE(WriteVoxels(tmp / "b", voxels, meta).ok());
  ASSERT_TRUE(BuildLod(tmp / "a", {}).ok());
  // Building again needs force.
  auto again = BuildLod(tmp / "a", {});
  EXPECT_EQ(again.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(again.status().message().find("--force"), std::string::npos);
  fs::copy(tmp / "a/lod", tmp / "b/lod", fs::copy_options::recursive);
  OpenOptions oo;
  auto b = Store::Open(tmp / "b", oo);
  ASSERT_TRUE(b.ok());
  auto p = LodPyramid::Open(tmp / "b", **b, oo);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(p.status().message().find("another store"), std::string::npos)
      << p.status().ToString();
  // Rebuilt with force, it belongs to b.
  LodBuildOptions lo;
  lo.force = true;
  ASSERT_TRUE(BuildLod(tmp / "b", lo).ok());
  EXPECT_TRUE(LodPyramid::Open(tmp / "b", **b, oo).ok());
}

TEST(Lod, StoreWithoutPyramidOpensAndSaysHowToAddOne) {
  TempDir tmp;
  const StoreMeta meta = MetaFor(5, 2, GridClass::kLevelSet, false);
  ASSERT_TRUE(WriteVoxels(tmp / "s", RandomVoxels(5, 1), meta).ok());
  OpenOptions oo;
  auto s = Store::Open(tmp / "s", oo);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ((*s)->meta().lod_level, 0);
  auto p = LodPyramid::Open(tmp / "s", **s, oo);
  EXPECT_EQ(p.status().code(), StatusCode::kNotFound);
  EXPECT_NE(p.status().message().find("--add-lod"), std::string::npos);
  // A coarse store is not a base store.
  ASSERT_TRUE(BuildLod(tmp / "s", {}).ok());
  auto c = BuildLod(tmp / "s/lod/1", {});
  EXPECT_FALSE(c.ok());
}

}  // namespace
}  // namespace vox::storage_test
