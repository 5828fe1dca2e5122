// Writes the fuzz targets' seed corpus into OUT_DIR/<target>/: small stores
// made by the real writer (a level set with colour, a fog volume, a top-only
// store), each in the three store-input modes; cameras, scenes and ray lines,
// valid and near-valid; the demo's cam.json and scene.json when DEMO_DIR is
// given; small .vdb files written by OpenVDB (level sets, double, fog,
// active tiles, an extra vec3 grid, an empty grid, no scalar grid, each
// with OpenVDB's compressions). Deterministic but for the .vdb files' UUIDs.
// Usage: fuzz_seed_gen OUT_DIR [DEMO_DIR]
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <tuple>
#include <iterator>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "core/shapes.h"
#include "render/job.h"
#include "storage/store.h"
#include "storage/store_writer.h"
#include "tests/fuzz/fuzz_input.h"

namespace fs = std::filesystem;

namespace {

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void Put(const fs::path& dir, const std::string& name, const std::string& bytes) {
  fs::create_directories(dir);
  std::ofstream(dir / name, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
}

// A store of `shape` (core/shapes.h) at `brick_level`, as its two files
// (and left in scratch when `keep`).
bool MakeStore(const std::string& shape, int brick_level, vox::GridClass gc, bool color,
               const fs::path& scratch, std::string* index, std::string* bricks,
               bool keep = false) {
  auto vol = vox::GenerateShape(shape);
  if (!vol.ok()) return false;
  vox::StoreMeta m;
  m.source_file = "seed";
  m.grid_name = "shape";
  m.grid_class = gc;
  m.levels = vol->levels;
  m.brick_level = std::min(brick_level, vol->levels);
  m.index_to_world = glm::dmat4(1.0);
  m.voxel_size = 1.0;
  m.has_normal = gc == vox::GridClass::kLevelSet;
  m.has_density = gc == vox::GridClass::kFogVolume;
  m.has_color = color;
  const int sub = m.levels - m.brick_level;
  const uint64_t mask = (uint64_t(1) << sub) - 1;
  std::map<std::tuple<uint64_t, uint64_t, uint64_t>, std::vector<vox::BrickVoxel>> by_brick;
  for (const vox::LeafPoint& p : vol->voxels) {
    vox::BrickVoxel v;
    v.x = uint32_t(p.x & mask);
    v.y = uint32_t(p.y & mask);
    v.z = uint32_t(p.z & mask);
    v.attr.normal = glm::normalize(glm::vec3(float(p.x % 5) + 0.5f, float(p.y % 3) - 1.f, 1.f));
    v.attr.density = float((p.x + p.y + p.z) % 10) / 10.f + 0.05f;
    v.attr.color = glm::vec3(float(p.x % 4) / 3.f, 0.5f, float(p.z % 2));
    by_brick[{p.x >> sub, p.y >> sub, p.z >> sub}].push_back(v);
  }
  const fs::path dir = scratch / (shape + "-" + std::to_string(brick_level));
  fs::remove_all(dir);
  auto w = vox::StoreWriter::Create(dir.string(), m, {});
  if (!w.ok()) return false;
  for (auto& [k, v] : by_brick)
    if (!(*w)->AddBrick(glm::u64vec3(std::get<0>(k), std::get<1>(k), std::get<2>(k)), std::move(v)).ok())
      return false;
  if (!(*w)->Finish().ok()) return false;
  *index = Slurp((dir / "index.vxi").string());
  *bricks = Slurp((dir / "bricks.vxb").string());
  if (!keep) fs::remove_all(dir);
  return true;
}

// The .vdb target's seeds: small grids of each kind the ingest reads, each
// written with OpenVDB's default compression (zip, active mask) and blosc
// when this OpenVDB has it; the sphere also uncompressed. Returns the number
// written.
int WriteVdbSeeds(const fs::path& dir) {
  openvdb::initialize();
  fs::create_directories(dir);
  using openvdb::Coord;
  auto sphere = [](float radius) {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius, openvdb::Vec3f(0.5f),
                                                                      1.0f, 2.0f);
    g->setName("sphere");
    return g;
  };
  std::vector<std::pair<std::string, openvdb::GridPtrVec>> files;
  files.push_back({"sphere", {sphere(5.0f)}});
  {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::DoubleGrid>(4.0, openvdb::Vec3d(-3.0),
                                                                       0.5, 2.0);
    g->setName("double");
    files.push_back({"double", {g}});
  }
  {
    auto fog = sphere(4.0f);
    openvdb::tools::sdfToFogVolume(*fog);
    fog->setName("density");
    files.push_back({"fog", {fog}});
  }
  {
    auto g = sphere(4.0f);
    g->tree().addTile(1, Coord(16, 0, 0), -1.0f, true);   // an occupied tile
    g->tree().addTile(1, Coord(-24, 8, 0), 2.0f, true);   // active, not occupied
    files.push_back({"tiles", {g}});
  }
  {
    auto g = sphere(4.0f);
    auto cd = openvdb::Vec3fGrid::create(openvdb::Vec3f(0.0f));
    cd->setName("Cd");
    for (int i = -4; i <= 4; ++i) cd->tree().setValue(Coord(i, i, 0), openvdb::Vec3f(0.1f * i, 0.5f, 1.0f));
    files.push_back({"color", {cd, g}});
  }
  {
    auto g = openvdb::FloatGrid::create(3.0f);
    g->setGridClass(openvdb::GRID_LEVEL_SET);
    g->setName("empty");
    files.push_back({"empty", {g}});
  }
  {
    auto cd = openvdb::Vec3fGrid::create();
    cd->setName("only-vec3");
    cd->tree().setValue(Coord(1, 2, 3), openvdb::Vec3f(1.0f));
    files.push_back({"no-scalar", {cd}});
  }
  std::vector<std::pair<std::string, uint32_t>> compressions = {
      {"none", openvdb::io::COMPRESS_NONE},
      {"zip", openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK}};
  if (openvdb::io::Archive::hasBloscCompression())
    compressions.push_back({"blosc", openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK});
  int n = 0;
  for (const auto& [name, grids] : files)
    for (const auto& [cname, c] : compressions) {
      // Uncompressed files are large (over 1 MB here): one is enough.
      if (c == openvdb::io::COMPRESS_NONE && name != "sphere") continue;
      openvdb::io::File f((dir / (name + "-" + cname + ".vdb")).string());
      f.setCompression(c);
      f.write(grids);
      f.close();
      ++n;
    }
  return n;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: fuzz_seed_gen OUT_DIR [DEMO_DIR]\n");
    return 2;
  }
  const fs::path out = argv[1];
  const fs::path scratch = out / ".scratch";
  fs::create_directories(scratch);
  int n = 0;
  struct StoreSeed {
    const char* shape;
    int brick_level;
    vox::GridClass gc;
    bool color;
  } stores[] = {{"sphere:16", 2, vox::GridClass::kLevelSet, true},
                {"sphere:8", 1, vox::GridClass::kFogVolume, false},
                {"sphere:8", 3, vox::GridClass::kLevelSet, false}};  // top-only
  for (const StoreSeed& s : stores) {
    std::string index, bricks;
    if (!MakeStore(s.shape, s.brick_level, s.gc, s.color, scratch, &index, &bricks)) {
      std::fprintf(stderr, "fuzz_seed_gen: cannot write a seed store for %s\n", s.shape);
      return 1;
    }
    for (uint8_t mode : {uint8_t(0), vox::fuzz::kFixChecksums,
                         uint8_t(vox::fuzz::kFixChecksums | vox::fuzz::kSkipBrickChecksums)}) {
      Put(out / "store", std::string(s.shape).replace(6, 1, "-") + "-" +
                             std::to_string(s.brick_level) + "-mode" + std::to_string(mode),
          vox::fuzz::JoinStoreInput(mode, index, bricks));
      ++n;
    }
  }
  // EXR target: two parts of a tiny render of the first store (4-byte length, part 1, part 2).
  {
    std::string index, bricks;
    if (!MakeStore("sphere:16", 2, vox::GridClass::kLevelSet, true, scratch, &index, &bricks,
                   /*keep=*/true)) {
      std::fprintf(stderr, "fuzz_seed_gen: cannot write the store for the EXR seeds\n");
      return 1;
    }
    std::string parts[2];
    for (int i = 0; i < 2; ++i) {
      vox::RenderJobOptions o;
      o.store_dir = (scratch / "sphere:16-2").string();
      o.exr_path = (scratch / ("p" + std::to_string(i + 1) + ".exr")).string();
      o.default_width = 24;
      o.default_height = 16;
      o.tile_size = 8;
      o.part.index = i + 1;
      o.part.count = 2;
      o.threads = 1;
      o.memory_bytes = uint64_t(256) << 20;
      o.quiet = true;
      vox::Status s = vox::RunRenderJob(o);
      if (!s.ok()) {
        std::fprintf(stderr, "fuzz_seed_gen: rendering the EXR seeds: %s\n", s.ToString().c_str());
        return 1;
      }
      parts[i] = Slurp(o.exr_path);
    }
    auto join = [](const std::string& a, const std::string& b) {
      std::string s;
      for (int k = 0; k < 4; ++k) s += char((uint32_t(a.size()) >> (8 * k)) & 0xff);
      return s + a + b;
    };
    Put(out / "exr", "parts-1-2", join(parts[0], parts[1]));
    Put(out / "exr", "parts-2-1", join(parts[1], parts[0]));
    Put(out / "exr", "parts-1-1", join(parts[0], parts[0]));
    n += 3;
  }
  fs::remove_all(scratch);

  n += WriteVdbSeeds(out / "vdb");

  // Parse target: byte 0 selects camera (0), scene (1), ray lines (2).
  const std::vector<std::pair<char, std::string>> texts = {
      {0, R"({"position":[1,2,3],"look_at":[0,0,0],"up":[0,1,0],"fov_deg":40,"width":64,"height":48})"},
      {0, R"({"position":[0,0,1e17],"look_at":[0,0,0],"up":[0,1,0],"projection":"orthographic","ortho_width":2,"width":8,"height":8})"},
      {0, R"({"position":[1,2,3],"look_at":[0,0,0],"up":[0,1,0],"fov_deg":40,"fov_deg":50,"width":64,"height":48})"},
      {0, R"({"position":[1,2,3],"look_at":[0,0,0],"up":[0,1,0],"fov_deg":1e-300,"width":64,"height":48})"},
      {1, R"({"ambient":[0.1,0.1,0.1],"lights":[{"type":"directional","direction":[0,-1,0],"color":[1,1,1],"intensity":1}]})"},
      {1, R"({"lights":[{"type":"point","position":[1,2,3],"color":[1,1,1],"intensity":2,"shadows":false}],"ambient":[0,0,0]})"},
      {1, R"({"background":{"top":[1,1,1],"bottom":[0,0,0]},"background":{"top":[0,0,0],"bottom":[0,0,0]}})"},
      {2, "0.5 0.5 -1 0 0 1\n# comment\n\n0x1p-3 2 3 1e300 -1e-300 0\n1 2 3 nan 0 0\n1 2\n"},
  };
  int i = 0;
  for (const auto& [kind, text] : texts) {
    Put(out / "parse", "text-" + std::to_string(i++), std::string(1, kind) + text);
    ++n;
  }
  if (argc > 2) {
    const fs::path demo = argv[2];
    Put(out / "parse", "demo-cam", std::string(1, char(0)) + Slurp((demo / "cam.json").string()));
    Put(out / "parse", "demo-scene", std::string(1, char(1)) + Slurp((demo / "scene.json").string()));
    n += 2;
  }
  std::printf("fuzz_seed_gen: %d seeds in %s\n", n, out.string().c_str());
  return 0;
}
