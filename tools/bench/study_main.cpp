// vox-study: the accuracy study's timed loops, driven by tools/bench/study.py; prints JSON.
//   vox-study precision STORE [--image N] [--per-family N] [--rounds N]
//   vox-study paper STORE... --images 256,512 [--threads N] [--rounds N]
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>


#include "core/util/parallel.h"
#include "render/frame.h"
#include "render/grid_transform.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "tools/bench/study.h"

namespace vox::bench {

Camera StudyCamera(int width, int height) {
  Camera c;
  c.position = {0, 0, 3};
  c.look_at = {0, 0, 0};
  c.up = {0, 1, 0};
  c.fov_deg = 40;
  c.width = width;
  c.height = height;
  c.projection = Projection::kPerspective;
  (void)c.Finalize("study camera");
  return c;
}

StatusOr<std::unique_ptr<Store>> OpenStudyStore(const std::string& dir) {
  OpenOptions oo;
  oo.cache_bytes = size_t(3) << 30;
  return Store::Open(dir, oo);
}

namespace {

// The counters of a frame, per ray.
nlohmann::json Counters(const FrameStats& st) {
  const auto& t = st.counters.trace;
  return {{"rays", t.rays},           {"moves", t.total_moves()},   {"driving", t.driving_moves},
          {"passive", t.passive_moves}, {"skips", t.skips},         {"cells", t.cells_visited},
          {"transitions", t.transitions}, {"brick_fetches", t.brick_fetches},
          {"hit_pixels", st.counters.hit_pixels}};
}

// One grid and image: every split, whole frames then first hits only, rotated per round.
StatusOr<nlohmann::json> PaperCase(Store* vol, int image, const PaperOptions& o) {
  const int levels = vol->meta().levels;
  const Camera cam = StudyCamera(image, image);
  VOX_ASSIGN_OR_RETURN(Scene scene, ParseScene(R"({"lights":[{"type":"directional",
      "direction":[-0.3,-0.5,-1],"shadows":false}],"material":{"specular":0}})", "diffuse scene"));
  std::vector<int> configs = {levels};  // single step first
  for (int n1 : {4, 5, 6, 7})
    if (n1 < levels && levels - n1 <= kMaxStepLevels) configs.push_back(n1);
  std::vector<std::unique_ptr<Renderer>> rs;
  std::vector<RenderTracer> tracers;
  for (int n1 : configs) {
    RenderOptions ro;
    ro.n1 = n1;
    ro.beam = false;  // the paper's walk from the occupied box, not vox's beam start distances
    VOX_ASSIGN_OR_RETURN(auto r, Renderer::Create(vol, cam, scene, ro));
    rs.push_back(std::move(r));
    VOX_ASSIGN_OR_RETURN(RenderTracer tr, RenderTracer::Create(vol->view(), n1));
    tracers.push_back(tr);
  }
  VOX_ASSIGN_OR_RETURN(GridTransform xf, GridTransform::FromMeta(vol->meta()));
  std::vector<Ray> rays(size_t(image) * image);
  for (int j = 0; j < image; ++j)
    for (int i = 0; i < image; ++i) {
      WorldRay w = cam.PixelRay(i + 0.5, j + 0.5);
      rays[size_t(j) * image + i] = Ray{xf.WorldToGrid(w.origin), xf.world_to_grid_linear * w.dir};
    }
  auto trace_pass = [&](const RenderTracer& tr) {
    std::atomic<uint64_t> hits{0};
    auto t0 = std::chrono::steady_clock::now();
    ParallelFor(
        0, rays.size(), 1024,
        [&](size_t b, size_t e) {
          uint64_t h = 0;
          for (size_t i = b; i != e; ++i) {
            auto got = tr.FirstHit(rays[i]);
            h += got.ok() && got->has_value();
          }
          hits += h;
        },
        o.threads);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  auto frame = [&](const Renderer& r) -> StatusOr<FrameStats> {
    FrameOptions fo;
    fo.threads = o.threads;
    FrameStats st;
    VOX_RETURN_IF_ERROR(RenderFrame(r, fo, &st));
    return st;
  };
  for (const auto& r : rs) VOX_RETURN_IF_ERROR(frame(*r).status());  // warm-up: pages in the bricks
  std::vector<nlohmann::json> out(configs.size());
  for (size_t c = 0; c < configs.size(); ++c)
    out[c] = {{"n1", configs[c]}, {"n2", levels - configs[c]}, {"frame_s", nlohmann::json::array()},
              {"first_hits_s", nlohmann::json::array()}};
  for (int round = 0; round < o.rounds; ++round)
    for (size_t k = 0; k < rs.size(); ++k) {
      const size_t c = (k + size_t(round)) % rs.size();
      VOX_ASSIGN_OR_RETURN(FrameStats st, frame(*rs[c]));
      out[c]["frame_s"].push_back(st.render_seconds);
      out[c]["counters"] = Counters(st);
    }
  for (int round = 0; round < o.rounds; ++round)
    for (size_t k = 0; k < rs.size(); ++k) {
      const size_t c = (k + size_t(round)) % rs.size();
      out[c]["first_hits_s"].push_back(trace_pass(tracers[c]));
    }
  fprintf(stderr, "vox-study: paper: %d^2 at %d levels measured\n", image, levels);
  return nlohmann::json{{"image", image}, {"levels", levels}, {"splits", out}};
}

}  // namespace

StatusOr<nlohmann::json> RunPaper(const PaperOptions& o) {
  nlohmann::json out = nlohmann::json::array();
  for (const std::string& path : o.stores) {
    VOX_ASSIGN_OR_RETURN(auto vol, OpenStudyStore(path));
    for (int image : o.images) {
      VOX_ASSIGN_OR_RETURN(nlohmann::json j, PaperCase(vol.get(), image, o));
      j["store"] = path;
      j["voxels"] = vol->meta().voxel_count;
      out.push_back(j);
    }
  }
  return out;
}

}  // namespace vox::bench

int main(int argc, char** argv) {
  auto usage = [] {
    fprintf(stderr,
            "usage: vox-study precision STORE [--image N] [--per-family N] [--rounds N]\n"
            "       vox-study paper STORE... --images N,N.. [--threads N] [--rounds N]\n");
    return 2;
  };
  if (argc < 3) return usage();
  const std::string part = argv[1];
  vox::bench::PrecisionOptions po;
  vox::bench::PaperOptions pa;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("--", 0) != 0) {
      pa.stores.push_back(a);
      po.store = a;
      continue;
    }
    if (i + 1 >= argc) return usage();
    const char* v = argv[++i];
    const int n = std::atoi(v);
    if (a == "--images") {
      std::stringstream ss(v);
      for (std::string item; std::getline(ss, item, ',');) pa.images.push_back(std::atoi(item.c_str()));
      if (std::count(pa.images.begin(), pa.images.end(), 0)) return usage();
    } else if (n <= 0) {
      fprintf(stderr, "vox-study: %s '%s': want a positive number\n", a.c_str(), v);
      return 2;
    } else if (a == "--image") {
      po.image = n;
    } else if (a == "--per-family") {
      po.per_family = n;
    } else if (a == "--rounds") {
      po.rounds = pa.rounds = n;
    } else if (a == "--threads") {
      pa.threads = n;
    } else {
      return usage();
    }
  }
  vox::StatusOr<nlohmann::json> r = part == "precision" ? vox::bench::RunPrecision(po)
                                    : part == "paper"   ? vox::bench::RunPaper(pa)
                                                        : vox::InvalidArgumentError("unknown part '" + part + "'");
  if (!r.ok()) {
    fprintf(stderr, "vox-study: %s\n", r.status().ToString().c_str());
    return 1;
  }
  printf("%s\n", r->dump().c_str());
  return 0;
}
