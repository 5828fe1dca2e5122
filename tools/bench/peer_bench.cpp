// vox-peer-bench: vox's renderer against NanoVDB's CPU ray caster on the same
// level set, camera, image and threads, in one process. The .vdb is read with
// OpenVDB and converted to a NanoVDB float grid in process; vox opens its
// store (ingesting the .vdb first when the store does not exist). Loading,
// conversion, ingest and store open are timed apart and excluded from the
// frame times.
//
// Both sides trace one primary ray per pixel centre of the same vox::Camera
// over the same tiles (render/tiles.h, Morton order, threads pulling tiles
// from one cursor in a TBB arena of --threads), each building its rays its
// own best way:
//   vox:  vox::RenderFrame of a Renderer with no lights (scene "lights": []),
//         no EXR: the renderer's primary-ray path (its batched screen rays),
//         hits shaded by the ambient term of the material, misses 0;
//   nano: NanoCaster below: float rays made once per pixel from the camera's
//         index-space frame, nanovdb::ZeroCrossing (HDDA over the tree's
//         levels, then voxel by voxel through the narrow band to the first
//         sign change), timed twice: as a bare loop (rays and hits) and as a
//         frame with vox's shading and channels. The index ray starts half a
//         voxel up on each axis so that NanoVDB's voxel ijk, the cell
//         [ijk, ijk + 1), is the cell OpenVDB's voxel ijk covers (centred on
//         ijk), as vox's grid space has it (render/grid_transform.h).
// After one warm-up frame each, --rounds warm frames of each run alternately
// (vox, nano shaded, nano bare, vox, ...), each timed by a stopwatch around
// the whole frame call; medians and best frames give rays/s and the ratios
// vox_over_nano_frame (against the shaded frame) and vox_over_nano_bare.
//
// Check: a frame of each is compared pixel by pixel. Hit masks may differ only
// on the silhouette ring (a pixel one side calls a hit and the other a miss
// must have a pixel within one pixel where the other side agrees with it),
// and where both hit, the distances are compared in voxels. A failed check
// (a pixel off the ring) exits 3: a peer that does less work is no peer.
//
//   vox-peer-bench IN.vdb [--store DIR] [--cam cam.json | --size WxH]
//                  [--rounds N] [--threads N] [--tile-size T] [--grid NAME]
//                  [--no-clip | --ab-clip] [--no-beam | --ab-beam] [--beam-block N]
// --ab-clip also times vox without the occupied-box clip (a third renderer in
// the alternation), for A/B in one run; --ab-beam likewise vox with the beam
// start distances toggled (RenderOptions::beam), and checks that both vox
// frames are bit-identical (exits 3 otherwise). --ab-beam-block N: the other
// vox has the beam on with N-pixel blocks instead of off.
#include <nanovdb/NanoVDB.h>
#include <nanovdb/util/HDDA.h>
#include <nanovdb/util/OpenToNanoVDB.h>
#include <nanovdb/util/Ray.h>
#include <openvdb/openvdb.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <glm/geometric.hpp>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/util/stopwatch.h"
#include "ingest/ingest.h"
#include "render/camera.h"
#include "render/frame.h"
#include "render/grid_transform.h"
#include "render/job.h"
#include "render/lod.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "render/tiles.h"
#include "storage/store.h"
#include "tools/common/flags.h"

namespace {

using vox::Status;
using vox::TileBuffer;
using vox::TileRect;

constexpr char kUsage[] =
    "usage: vox-peer-bench IN.vdb [--store DIR] [--cam cam.json | --size WxH] [--rounds N]\n"
    "                      [--threads N] [--tile-size T] [--grid NAME] [--no-clip | --ab-clip]\n"
    "                      [--no-beam | --ab-beam] [--beam-block N] [--lod F]\n"
    "  --store      the vox store of IN.vdb (ingested there first when DIR does not exist;\n"
    "               default: a temporary store, removed at the end)\n"
    "  --cam        camera (default: vox-render's default camera, --size pixels, 1024x1024)\n"
    "  --rounds     warm frames of each renderer, alternating (at least 5; default 7)\n"
    "  --threads    threads of both renderers (default 2)\n"
    "  --tile-size  tile side of both (default 64)\n"
    "  --grid       the level-set grid (default: the file's first float grid)\n"
    "  --no-clip    vox traces without clipping rays to the occupied box\n"
    "  --ab-clip    time vox with and without the clip, alternating with NanoVDB\n"
    "  --no-beam    vox traces without beam start distances\n"
    "  --ab-beam    time vox with and without beam start distances, alternating with NanoVDB\n"
    "  --beam-block pixels per side of a beam block (default 8)\n"
    "  --ab-beam-block N  with --ab-beam: the other vox has beam blocks of N, not no beam\n"
    "  --lod F      vox's level of detail, as vox-render's (default: 1 when the store has a\n"
    "               pyramid, else 0); --lod 0: the exact frame, for exact comparisons\n";

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Runs fn(rect, worker) over every tile of `layout` with `threads` workers
// pulling tiles in render order from one cursor (as vox::RenderFrame does).
template <class Worker, class Fn>
void ForTiles(const vox::TileLayout& layout, int threads,
              tbb::enumerable_thread_specific<Worker>& workers, Fn&& fn) {
  std::atomic<size_t> cursor{0};
  const auto& order = layout.order();
  tbb::task_arena arena(threads);
  arena.execute([&] {
    tbb::parallel_for(0, threads, [&](int) {
      Worker& w = workers.local();
      for (size_t i; (i = cursor.fetch_add(1)) < order.size();) fn(order[i], w);
    });
  });
}

// NanoVDB's side: the grid, the camera and the frame's tile loop, built as
// an independent caster builds them: one float ray per pixel, made once from
// the camera's index-space frame (direction = forward + sx right + sy up,
// sx and sy linear in the pixel, normalised in float), then HDDA +
// ZeroCrossing. Two frames of it:
//   bare:   the ray and the hit only (A and Z written: what a bare loop does);
//   shaded: the same, plus vox's shading with no lights (the ambient colour
//           on a hit; on a miss 0, or the background gradient from the same
//           direction when the scene puts it in the EXR), writing the
//           channels vox's frame writes.
// Z is the planar depth, as vox's (the world distance over |direction|).
class NanoCaster {
 public:
  NanoCaster(const nanovdb::FloatGrid* grid, const vox::Camera& cam, const vox::Scene& scene)
      : grid_(grid), scene_(scene) {
    perspective_ = cam.projection == vox::Projection::kPerspective;
    auto index_dir = [&](const glm::dvec3& d) {
      return grid_->worldToIndexDir(nanovdb::Vec3d(d.x, d.y, d.z));
    };
    const nanovdb::Vec3d eye = grid_->worldToIndex(
        nanovdb::Vec3d(cam.position.x, cam.position.y, cam.position.z));
    // +0.5: NanoVDB's voxel ijk is the cell [ijk, ijk + 1); vox's and
    // OpenVDB's voxel ijk is centred on ijk (render/grid_transform.h).
    eye_ = nanovdb::Vec3f(float(eye[0] + 0.5), float(eye[1] + 0.5), float(eye[2] + 0.5));
    forward_ = nanovdb::Vec3f(index_dir(cam.forward()));
    right_ = nanovdb::Vec3f(index_dir(cam.right()));
    up_ = nanovdb::Vec3f(index_dir(cam.true_up()));
    // Camera::ScreenX(ix + 0.5) and ScreenY(iy + 0.5) as sx0 + ix dsx, sy0 + iy dsy.
    sx0_ = float((1.0 / cam.width - 1.0) * cam.scale_x());
    dsx_ = float(2.0 * cam.scale_x() / cam.width);
    sy0_ = float((1.0 - 1.0 / cam.height) * cam.scale_y());
    dsy_ = float(-2.0 * cam.scale_y() / cam.height);
    voxel_ = float(grid_->voxelSize()[0]);
    surface_ = scene_.material.color * scene_.ambient;
  }

  template <bool kShaded>
  void RenderTile(const TileRect& rect, TileBuffer* buf) const {
    auto acc = grid_->getAccessor();
    const float inf = std::numeric_limits<float>::infinity();
    for (int py = 0; py < rect.h; ++py) {
      const float sy = sy0_ + float(rect.y0 + py) * dsy_;
      for (int px = 0; px < rect.w; ++px) {
        const float sx = sx0_ + float(rect.x0 + px) * dsx_;
        nanovdb::Vec3f origin = eye_, dir = forward_;
        float world_len = 1.0f;  // |forward + sx right + sy up| in world units
        if (perspective_) {
          dir = forward_ + right_ * sx + up_ * sy;
          world_len = std::sqrt(1.0f + sx * sx + sy * sy);
        } else {
          origin = eye_ + right_ * sx + up_ * sy;
        }
        const float len = dir.length();
        nanovdb::Ray<float> ray(origin, dir * (1.0f / len));
        nanovdb::Coord ijk;
        float v = 0, t = 0;
        const bool hit = nanovdb::ZeroCrossing(ray, acc, ijk, v, t);
        *buf->at(vox::kChA, px, py) = hit ? 1.0f : 0.0f;
        *buf->at(vox::kChZ, px, py) = hit ? t * voxel_ / world_len : inf;
        if constexpr (kShaded) {
          glm::dvec3 c = hit ? surface_ : glm::dvec3(0.0);  // premultiplied: a miss is 0
          if (!hit && scene_.background_in_exr) {
            // vox's background: u = (dir . up + 1) / 2 of the unit world direction
            const float u = perspective_ ? 0.5f * (sy / world_len + 1.0f) : 0.5f;
            c = glm::mix(scene_.background_bottom, scene_.background_top,
                         double(std::clamp(u, 0.0f, 1.0f)));
          }
          *buf->at(vox::kChR, px, py) = float(c.r);
          *buf->at(vox::kChG, px, py) = float(c.g);
          *buf->at(vox::kChB, px, py) = float(c.b);
        }
      }
    }
  }

 private:
  const nanovdb::FloatGrid* grid_;
  const vox::Scene& scene_;
  bool perspective_ = true;
  nanovdb::Vec3f eye_, forward_, right_, up_;
  float sx0_ = 0, dsx_ = 0, sy0_ = 0, dsy_ = 0, voxel_ = 1;
  glm::dvec3 surface_{0.0};
};

struct Image {
  int w = 0, h = 0;
  std::vector<uint8_t> hit;
  std::vector<float> z;
  void Resize(int width, int height) {
    w = width;
    h = height;
    hit.assign(size_t(w) * h, 0);
    z.assign(size_t(w) * h, 0.0f);
  }
  void Put(const TileRect& r, const TileBuffer& b) {
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x) {
        const size_t i = size_t(r.y0 + y) * w + (r.x0 + x);
        hit[i] = b.ch[vox::kChA][size_t(y) * b.size + x] > 0.5f;
        z[i] = b.ch[vox::kChZ][size_t(y) * b.size + x];
      }
  }
};

struct Worker {
  TileBuffer buf;
  std::unique_ptr<vox::Renderer::ThreadState, vox::Renderer::ThreadStateDeleter> state;
  vox::RenderCounters counters;
};

int Fail(const std::string& msg) {
  fprintf(stderr, "vox-peer-bench: %s\n", msg.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string vdb_path, store_path, cam_path, grid_name;
  int rounds = 7, threads = 2, tile = 64, width = 1024, height = 1024;
  bool clip = true, ab_clip = false, beam = true, ab_beam = false;
  int beam_block = 8, ab_beam_block = 0;
  std::optional<double> lod;  // unset: vox-render's default (OpenRenderStores)
  vox::FlagReader flags(argc, argv);
  auto usage = [](const std::string& error) {
    if (!error.empty()) fprintf(stderr, "vox-peer-bench: %s\n", error.c_str());
    fprintf(stderr, "%s", kUsage);
    return 2;
  };
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (flags.IsHelp()) {
      printf("%s", kUsage);
      return 0;
    }
    if (a == "--no-clip") {
      clip = false;
      continue;
    }
    if (a == "--ab-clip") {
      ab_clip = true;
      continue;
    }
    if (a == "--no-beam") {
      beam = false;
      continue;
    }
    if (a == "--ab-beam") {
      ab_beam = true;
      continue;
    }
    if (!flags.IsFlag()) {
      if (!vdb_path.empty()) return usage("more than one input: " + vdb_path + " and " + a);
      vdb_path = a;
      continue;
    }
    if (a != "--store" && a != "--cam" && a != "--size" && a != "--rounds" && a != "--threads" &&
        a != "--tile-size" && a != "--grid" && a != "--beam-block" &&
        a != "--ab-beam-block" && a != "--lod")
      return usage("unknown flag " + a);
    const std::optional<std::string> v = flags.Value();
    if (!v) return usage(a + " needs a value");
    bool ok = true;
    if (a == "--store") {
      store_path = *v;
    } else if (a == "--cam") {
      cam_path = *v;
    } else if (a == "--grid") {
      grid_name = *v;
    } else if (a == "--rounds") {
      ok = vox::ParseInt(*v, 5, 1000, &rounds);
    } else if (a == "--threads") {
      ok = vox::ParseInt(*v, 1, 4096, &threads);
    } else if (a == "--beam-block") {
      ok = vox::ParseInt(*v, 1, 4096, &beam_block);
    } else if (a == "--ab-beam-block") {
      ok = vox::ParseInt(*v, 1, 4096, &ab_beam_block);
      ab_beam = ok;
    } else if (a == "--tile-size") {
      ok = vox::ParseInt(*v, vox::kMinTileSize, vox::kMaxTileSize, &tile);
    } else if (a == "--lod") {
      auto f = vox::ParseLodFactor("--lod", *v);
      if (!f.ok()) return usage(f.status().message());
      lod = *f;
    } else {
      const size_t x = v->find('x');
      ok = x != std::string::npos &&
           vox::ParseInt(v->substr(0, x), 1, vox::kMaxImageSide, &width) &&
           vox::ParseInt(v->substr(x + 1), 1, vox::kMaxImageSide, &height);
    }
    if (!ok) return usage(a + " '" + *v + "': out of range or not a number");
  }
  if (vdb_path.empty()) return usage("no input .vdb given");
  if (ab_clip && ab_beam) return usage("--ab-clip and --ab-beam: one A/B at a time");
  namespace fs = std::filesystem;
  nlohmann::json out;
  out["vdb"] = vdb_path;

  // NanoVDB: read the grid with OpenVDB and convert it.
  openvdb::initialize();
  vox::Stopwatch clock;
  openvdb::FloatGrid::Ptr vdb_grid;
  try {
    openvdb::io::File file(vdb_path);
    file.open();
    openvdb::GridBase::Ptr base;
    if (!grid_name.empty()) {
      base = file.readGrid(grid_name);
    } else {
      for (auto it = file.beginName(); it != file.endName() && !base; ++it) {
        openvdb::GridBase::Ptr g = file.readGrid(*it);
        if (g->isType<openvdb::FloatGrid>()) base = g;
      }
    }
    file.close();
    if (!base) return Fail(vdb_path + ": no float grid");
    vdb_grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    if (!vdb_grid) return Fail(vdb_path + ": grid '" + grid_name + "' is not a float grid");
    if (vdb_grid->getGridClass() != openvdb::GRID_LEVEL_SET)
      return Fail(vdb_path + ": grid '" + vdb_grid->getName() +
                  "' is not a level set (NanoVDB's ZeroCrossing needs one)");
  } catch (const std::exception& e) {
    return Fail(vdb_path + ": cannot read: " + e.what());
  }
  out["vdb_load_seconds"] = clock.Lap();
  auto handle = nanovdb::openToNanoVDB(*vdb_grid);
  const nanovdb::FloatGrid* nano = handle.grid<float>();
  if (nano == nullptr) return Fail(vdb_path + ": NanoVDB conversion failed");
  out["nanovdb_convert_seconds"] = clock.Lap();
  out["nanovdb_bytes"] = handle.size();
  out["active_voxels"] = vdb_grid->activeVoxelCount();
  vdb_grid.reset();

  // vox: the store, ingested first when missing.
  bool temp_store = false;
  if (store_path.empty()) {
    store_path = (fs::temp_directory_path() / ("vox-peer-" + std::to_string(getpid()) + ".store"))
                     .string();
    temp_store = true;
  }
  struct Cleanup {
    std::string path;
    ~Cleanup() {
      std::error_code ec;
      if (!path.empty()) fs::remove_all(path, ec);
    }
  } cleanup{temp_store ? store_path : std::string()};
  if (!fs::exists(store_path)) {
    vox::IngestOptions io;
    io.input = vdb_path;
    io.output = store_path;
    io.grid_name = grid_name;
    io.threads = threads;
    auto st = vox::Ingest(io);
    if (!st.ok()) return Fail(st.status().ToString());
    out["ingest_seconds"] = clock.Lap();
  }
  clock.Lap();
  vox::OpenOptions oo;
  oo.cache_bytes = size_t(4) << 30;
  auto stores = vox::OpenRenderStores(store_path, lod, oo);
  if (!stores.ok()) return Fail(stores.status().ToString());
  vox::Store* store = stores->base.get();
  out["store"] = store_path;
  out["store_open_seconds"] = clock.Lap();

  vox::Camera cam;
  if (!cam_path.empty()) {
    auto c = vox::LoadCamera(cam_path);
    if (!c.ok()) return Fail(c.status().ToString());
    cam = *c;
  } else {
    glm::dvec3 lo, hi;
    vox::WorldBounds(store->meta(), &lo, &hi);
    cam = vox::DefaultCamera(lo, hi, width, height);
  }
  out["camera"] = nlohmann::json::parse(cam.ToJson());
  vox::Scene scene;
  scene.default_lights = false;  // "lights": [] -- primary rays only
  vox::RenderOptions ro;
  ro.clip_to_occupied = clip;
  ro.beam = beam;
  ro.beam_block = beam_block;
  ro.lod = stores->lod;
  for (vox::Store* level : stores->levels) ro.lod_levels.push_back(level);
  out["lod"] = stores->lod;
  auto renderer = vox::Renderer::Create(store, cam, scene, ro);
  if (!renderer.ok()) return Fail(renderer.status().ToString());
  if (!(*renderer)->passes().ToString().starts_with("primary") || (*renderer)->passes().shadows)
    return Fail("expected a level set rendered with primary rays only, got " +
                (*renderer)->passes().ToString());
  NanoCaster caster(nano, cam, (*renderer)->scene());
  const vox::TileLayout layout(cam.width, cam.height, tile);
  const double pixels = double(cam.width) * cam.height;

  // The frames: one warm-up each, then alternating rounds.
  tbb::enumerable_thread_specific<Worker> workers([&] {
    Worker w;
    w.buf.Allocate(tile, vox::ImageLayers{});
    w.state = (*renderer)->NewThreadState();
    return w;
  });
  std::unique_ptr<vox::Renderer> plain;  // --ab-clip / --ab-beam: vox with it toggled
  if (ab_clip || ab_beam) {
    vox::RenderOptions po = ro;
    if (ab_clip) po.clip_to_occupied = !clip;
    if (ab_beam) po.beam = !beam;
    if (ab_beam_block > 0) {
      po.beam = true;
      po.beam_block = ab_beam_block;
    }
    auto p = vox::Renderer::Create(store, cam, scene, po);
    if (!p.ok()) return Fail(p.status().ToString());
    plain = std::move(p).value();
  }
  // Every frame is timed the same way: a stopwatch around the call.
  std::vector<double> vox_s, bare_s, shaded_s, plain_s;
  auto vox_frame = [&](vox::FrameStats* st, const vox::Renderer* r,
                       std::vector<double>* seconds) {
    vox::FrameOptions fo;
    fo.threads = threads;
    fo.tile_size = tile;
    *st = vox::FrameStats();  // RenderFrame adds to the counters
    vox::Stopwatch sw;
    Status s = vox::RenderFrame(r ? *r : **renderer, fo, st);
    if (seconds) seconds->push_back(sw.Seconds());
    return s;
  };
  auto nano_frame = [&](bool shaded, std::vector<double>* seconds) {
    vox::Stopwatch sw;
    ForTiles(layout, threads, workers, [&](const TileRect& r, Worker& w) {
      if (shaded)
        caster.RenderTile<true>(r, &w.buf);
      else
        caster.RenderTile<false>(r, &w.buf);
    });
    const double t = sw.Seconds();
    if (seconds) seconds->push_back(t);
    return t;
  };
  vox::FrameStats st;
  std::vector<double> first;
  if (Status s = vox_frame(&st, nullptr, &first); !s.ok()) return Fail(s.ToString());
  if (plain) {
    if (Status s = vox_frame(&st, plain.get(), nullptr); !s.ok()) return Fail(s.ToString());
  }
  out["vox_first_seconds"] = first[0];
  out["nano_first_seconds"] = nano_frame(true, nullptr);
  nano_frame(false, nullptr);
  vox::RenderCounters vox_counters;
  for (int r = 0; r < rounds; ++r) {
    if (Status s = vox_frame(&st, nullptr, &vox_s); !s.ok()) return Fail(s.ToString());
    vox_counters = st.counters;
    nano_frame(true, &shaded_s);
    nano_frame(false, &bare_s);
    if (plain) {
      if (Status s = vox_frame(&st, plain.get(), &plain_s); !s.ok()) return Fail(s.ToString());
    }
  }
  auto best = [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); };
  const double vm = Median(vox_s), nm = Median(shaded_s), bm = Median(bare_s);
  out["threads"] = threads;
  out["tile_size"] = tile;
  out["split"] = (*renderer)->SplitString();
  out["clip_to_occupied"] = clip;
  out["beam"] = beam;
  out["beam_block"] = beam_block;
  if (ab_beam_block > 0) out["other_beam_block"] = ab_beam_block;
  out["vox_seconds"] = vox_s;
  out["nano_shaded_seconds"] = shaded_s;
  out["nano_bare_seconds"] = bare_s;
  out["vox_median_seconds"] = vm;
  out["nano_shaded_median_seconds"] = nm;
  out["nano_bare_median_seconds"] = bm;
  out["vox_rays_per_second"] = pixels / vm;
  out["nano_shaded_rays_per_second"] = pixels / nm;
  out["nano_bare_rays_per_second"] = pixels / bm;
  // vox's frame against NanoVDB's shaded frame (the same rays' work and
  // output) and against its bare loop (rays and hits only), as medians of the
  // alternated rounds and as best frames.
  out["vox_over_nano_frame"] = nm / vm;
  out["vox_over_nano_bare"] = bm / vm;
  out["vox_over_nano_frame_best"] = best(shaded_s) / best(vox_s);
  out["vox_over_nano_bare_best"] = best(bare_s) / best(vox_s);
  out["vox_dda_moves_per_ray"] = double(vox_counters.trace.total_moves()) / pixels;
  if (plain && ab_beam) {
    const double pm = Median(plain_s);
    out["vox_other_beam_seconds"] = plain_s;
    out["vox_other_beam_rays_per_second"] = pixels / pm;
    out["vox_other_beam_over_nano_frame"] = nm / pm;
    out["beam_speedup"] = beam ? pm / vm : vm / pm;
    if (ab_beam_block > 0)
      fprintf(stderr, "vox with beam blocks of %d: %.2fx the rays/s with blocks of %d\n",
              beam_block, pm / vm, ab_beam_block);
    else
      fprintf(stderr, "vox with beam start distances: %.2fx the rays/s without them\n",
              beam ? pm / vm : vm / pm);
  } else if (plain) {
    const double pm = Median(plain_s);
    out["vox_other_clip_seconds"] = plain_s;
    out["vox_other_clip_rays_per_second"] = pixels / pm;
    out["vox_other_clip_over_nano_frame"] = nm / pm;
    out["clip_speedup"] = clip ? pm / vm : vm / pm;
    fprintf(stderr, "vox with the occupied-box clip: %.2fx the rays/s without it\n",
            clip ? pm / vm : vm / pm);
  }

  // The check: one frame of each, pixel by pixel.
  Image vi, ni;
  vi.Resize(cam.width, cam.height);
  ni.Resize(cam.width, cam.height);
  std::atomic<bool> failed{false};
  ForTiles(layout, threads, workers, [&](const TileRect& r, Worker& w) {
    if (!(*renderer)->RenderTile(r, &w.buf, &w.counters, w.state.get()).ok()) failed = true;
    vi.Put(r, w.buf);
    caster.RenderTile<true>(r, &w.buf);
    ni.Put(r, w.buf);
  });
  if (failed) return Fail("vox RenderTile failed in the check");
  uint64_t ab_differ = 0;  // --ab-beam: pixels whose bits differ between the two vox frames
  if (plain && ab_beam) {
    Image pi;
    pi.Resize(cam.width, cam.height);
    ForTiles(layout, threads, workers, [&](const TileRect& r, Worker& w) {
      if (!plain->RenderTile(r, &w.buf, &w.counters, w.state.get()).ok()) failed = true;
      pi.Put(r, w.buf);
    });
    if (failed) return Fail("vox RenderTile failed in the check");
    for (size_t i = 0; i < vi.hit.size(); ++i)
      if (vi.hit[i] != pi.hit[i] || std::memcmp(&vi.z[i], &pi.z[i], sizeof vi.z[i]) != 0)
        ++ab_differ;
    out["beam_ab_pixels_differ"] = ab_differ;
    fprintf(stderr, "vox with and without the beam: %llu pixels differ\n",
            (unsigned long long)ab_differ);
  }
  const double voxel = store->meta().voxel_size;
  uint64_t vox_hits = 0, nano_hits = 0, both = 0, ring = 0, off_ring = 0;
  std::vector<double> dz;
  auto near = [](const Image& img, int x, int y, uint8_t want) {
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = x + dx, yy = y + dy;
        if (xx >= 0 && yy >= 0 && xx < img.w && yy < img.h &&
            img.hit[size_t(yy) * img.w + xx] == want)
          return true;
      }
    return false;
  };
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const size_t i = size_t(y) * cam.width + x;
      vox_hits += vi.hit[i];
      nano_hits += ni.hit[i];
      if (vi.hit[i] && ni.hit[i]) {
        ++both;
        dz.push_back(std::fabs(double(vi.z[i]) - double(ni.z[i])) / voxel);
      } else if (vi.hit[i] != ni.hit[i]) {
        // On the ring: each side has the other's answer within one pixel.
        if (near(ni, x, y, vi.hit[i]) && near(vi, x, y, ni.hit[i]))
          ++ring;
        else
          ++off_ring;
      }
    }
  std::sort(dz.begin(), dz.end());
  auto q = [&](double f) { return dz.empty() ? 0.0 : dz[size_t(f * double(dz.size() - 1))]; };
  out["check"] = {{"vox_hit_pixels", vox_hits},
                  {"nano_hit_pixels", nano_hits},
                  {"both_hit", both},
                  {"miss_fraction", 1.0 - double(vox_hits) / pixels},
                  {"differ_on_ring", ring},
                  {"differ_off_ring", off_ring},
                  {"depth_diff_voxels_median", q(0.5)},
                  {"depth_diff_voxels_p99", q(0.99)},
                  {"depth_diff_voxels_max", q(1.0)},
                  {"ok", off_ring == 0}};
  printf("%s\n", out.dump(2).c_str());
  fprintf(stderr,
          "vox %.3g rays/s; NanoVDB shaded %.3g, bare %.3g rays/s: vox/NanoVDB %.2fx (frame), "
          "%.2fx (bare loop), miss fraction %.2f; check %s (%llu pixels differ on the "
          "silhouette ring, %llu off it)\n",
          pixels / vm, pixels / nm, pixels / bm, nm / vm, bm / vm, 1.0 - double(vox_hits) / pixels,
          off_ring == 0 ? "ok" : "FAILED", (unsigned long long)ring, (unsigned long long)off_ring);
  return off_ring == 0 && ab_differ == 0 ? 0 : 3;
}
