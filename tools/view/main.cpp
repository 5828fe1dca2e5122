// vox-view: serves one local web page (127.0.0.1 only) that frames a vox
// store interactively. Each frame is rendered in-process by
// vox::RunRenderJob, the function vox-render runs, over a RenderSession
// opened once: the store, its pyramid and their brick caches stay warm from
// frame to frame under the one memory budget. A request's camera (cam.json
// text, or --view angles), scene (scene.json text), --size and --lod are
// applied as vox-render's flags (tools/common/options.h), so a frame and
// vox-render's EXR for the same files are equal, bit for bit. A newer /frame
// request stops the one in flight (RenderJobOptions::interrupted). /probe
// traces the ray under the cursor with vox-probe's Prober over the same
// store; /save gives (and with --out writes) the last refined frame's
// cam.json, scene.json and vox-render command line (tools/view/saves.h).
#include <httplib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/ray_text.h"
#include "core/util/stopwatch.h"
#include "render/camera.h"
#include "render/grid_transform.h"
#include "render/job.h"
#include "render/scene.h"
#include "tools/common/cli.h"
#include "tools/common/flags.h"
#include "tools/common/options.h"
#include "tools/common/prober.h"
#include "tools/common/tool_main.h"
#include "tools/view/page.h"
#include "tools/view/saves.h"

namespace {

using vox::FlagArity;
using json = nlohmann::json;
// The render flags apply as vox-render's (vox::ApplyRenderFlag).
const vox::OptionSpec kViewOptions[] = {
    {"--port", FlagArity::kValue, "N", "Server", "the port on 127.0.0.1 (default 0: a free one)"},
    {"--out", FlagArity::kValue, "DIR", "Server",
     "Save also writes view-NNN.cam.json, .scene.json and .sh here (new names only)"},
    {"--scene", FlagArity::kValue, "scene.json", "Render", "as vox-render's --scene"},
    {"--memory-mb", FlagArity::kValue, "M", "Render", "as vox-render's --memory-mb"},
    {"--threads", FlagArity::kValue, "N", "Render", "as vox-render's --threads"},
};

struct ViewFlags {
  int port = 0;
  std::string out_dir;
};

vox::Status ApplyViewFlag(vox::RenderJobOptions* o, ViewFlags* f, const std::string& flag,
                          const std::string& value) {
  if (flag == "--out") {
    f->out_dir = value;
    return vox::OkStatus();
  }
  if (flag != "--port") return vox::ApplyRenderFlag(o, flag, value);
  if (!vox::ParseInt(value, 0, 65535, &f->port))
    return vox::InvalidArgumentError("--port " + value + ": must be in 0..65535");
  return vox::OkStatus();
}

const vox::CommandLineSpec kCommandLine{
    "vox-view", "vox-view STORE_DIR [options]",
    "Serves a web page on 127.0.0.1 that renders the vox store STORE_DIR as the mouse and the "
    "keyboard move the camera, and gives the cam.json, scene.json and vox-render command line "
    "of the view. Prints the page's address.",
    kViewOptions,
    "Only the page and its requests are served. Exit codes: 0 stopped, 1 failed, 2 bad "
    "command line.\n"};

// What the last frame was made of: its camera (cam.json, as --stats gives
// it), its scene (scene.json) and the level of detail in effect.
struct FrameRecord {
  std::string camera, scene;
  std::string lod;  // the --lod factor, as --stats prints it
};

struct Viewer {
  vox::RenderJobOptions base;
  std::unique_ptr<vox::RenderSession> session;
  std::unique_ptr<vox::Prober> prober;
  vox::GridTransform grid;
  glm::i64vec3 origin{0};
  std::string base_scene;  // scene.json text of --scene (or the default scene)
  vox::SaveTarget save;
  std::atomic<uint64_t> generation{0};
  std::mutex render_mutex;  // one frame at a time: the memory budget is the process's
  std::mutex probe_mutex;   // the Prober traces on one thread at a time
  std::mutex last_mutex;
  std::string last_stats = "{}";
  FrameRecord last, last_refined;
  bool have_last = false, have_refined = false;
};

void Reply(httplib::Response& res, int status, const std::string& text) {
  res.status = status;
  res.set_content(text + "\n", "text/plain");
}

// The request's query parameters as vox-render flags and files, over `base`:
// cam (cam.json text) or az and el (--view); w and h (--size); lod; scene
// (scene.json text).
vox::Status ApplyQuery(const Viewer& v, const httplib::Request& req, vox::RenderJobOptions* o) {
  const auto get = [&](const char* key) { return req.get_param_value(key); };
  if (!req.has_param("w") || !req.has_param("h"))
    return vox::InvalidArgumentError("a frame request needs w and h");
  if (req.has_param("cam")) {
    o->camera_path.clear();
    o->camera_json = get("cam");
  } else if (req.has_param("az") && req.has_param("el")) {
    VOX_RETURN_IF_ERROR(vox::ApplyRenderFlag(o, "--view", get("az") + "," + get("el")));
  } else {
    return vox::InvalidArgumentError("a frame request needs cam, or az and el");
  }
  VOX_RETURN_IF_ERROR(vox::ApplyRenderFlag(o, "--size", get("w") + "x" + get("h")));
  // Small tiles: a newer frame stops the one in flight between tiles, so a move waits for a
  // 16-pixel tile of a full-size frame, a sixteenth of a 64-pixel one's work (the pixels do not
  // depend on the tile size; the border rays of 16-pixel tiles add about 2% to a frame).
  // Coarse frames (fmt=rgba8) take 32-pixel tiles, a few dozen for the two threads to share.
  o->tile_size = get("fmt") == "rgba8" ? 32 : 16;
  if (req.has_param("lod")) VOX_RETURN_IF_ERROR(vox::ApplyRenderFlag(o, "--lod", get("lod")));
  if (req.has_param("aa"))
    VOX_RETURN_IF_ERROR(vox::ApplyRenderFlag(o, "--silhouette-aa", get("aa")));
  o->scene_path.clear();
  o->scene_json = req.has_param("scene") ? get("scene") : v.base_scene;
  return vox::OkStatus();
}

// A frame as the page paints it: premultiplied RGBA `rgba` (w x h, from the
// top row) over the scene's background, its colour blended from the top
// row's to the bottom row's, each channel through display gamma 1/2.2 in
// 4096 steps, 8 bits per channel, alpha 255. The same arithmetic, in the
// same order, as the page's own painting of a float frame (page.html), so
// both give the same bytes: a quarter of the float frame's, for the coarse
// frames that follow the mouse.
std::string PaintedRgba8(const std::vector<float>& rgba, int w, int h, const vox::Scene& scene) {
  static const std::array<uint8_t, 4096> gamma = [] {
    std::array<uint8_t, 4096> g{};
    for (int i = 0; i < 4096; ++i)
      g[size_t(i)] = uint8_t(std::floor(std::pow(i / 4095.0, 1 / 2.2) * 255 + 0.5));
    return g;
  }();
  const auto step = [](double v) {  // Math.max(0, Math.min(4095, v * 4095 + 0.5)) | 0
    const double x = v * 4095 + 0.5;
    return std::isnan(x) ? 0 : int(std::max(0.0, std::min(4095.0, x)));
  };
  std::string out(size_t(w) * size_t(h) * 4, '\0');
  auto* d = reinterpret_cast<uint8_t*>(out.data());
  for (int y = 0; y < h; ++y) {
    const double t = (y + 0.5) / h;
    double b[3];
    for (int c = 0; c < 3; ++c)
      b[c] = scene.background_top[c] + (scene.background_bottom[c] - scene.background_top[c]) * t;
    for (size_t p = size_t(y) * size_t(w) * 4, e = p + size_t(w) * 4; p < e; p += 4) {
      const double k = 1 - double(rgba[p + 3]);
      for (int c = 0; c < 3; ++c)
        d[p + size_t(c)] = gamma[size_t(step(rgba[p + size_t(c)] + k * b[c]))];
      d[p + 3] = 255;
    }
  }
  return out;
}

// The panel's figures out of a frame's --stats.
json PanelOf(const json& stats) {
  const json& lod = stats["lod"];
  const json& cache = stats["cache"];
  json p;
  p["ms"] = stats["timings"].value("render_seconds", 0.0) * 1e3;
  p["job_ms"] = stats["timings"].value("total_seconds", 0.0) * 1e3;
  p["lod"] = lod.value("factor", 0.0);
  p["stops_by_level"] = lod.value("stops_by_level", json::object());
  p["bricks_read"] =
      lod.contains("bricks_paged_total") ? lod["bricks_paged_total"] : cache["misses"];
  p["bytes_read"] = lod.contains("brick_bytes_read_total") ? lod["brick_bytes_read_total"]
                                                           : stats["io"]["brick_bytes_read"];
  p["cache_resident"] = cache["bytes_resident"];
  p["cache_capacity"] = cache["capacity"];
  p["budget"] = stats["memory"]["total"];
  p["rss"] = stats["memory"]["process"]["rss"];
  return p;
}

void ServeFrame(Viewer* v, const httplib::Request& req, httplib::Response& res) {
  const vox::Stopwatch handler;
  vox::RenderJobOptions o = v->base;
  if (vox::Status s = ApplyQuery(*v, req, &o); !s.ok()) return Reply(res, 400, s.ToString());
  // The scene checked before the frame: a bad one is the request's fault.
  auto scene = vox::ParseScene(o.scene_json, "scene");
  if (!scene.ok()) return Reply(res, 400, scene.status().ToString());
  const std::string format = req.has_param("fmt") ? req.get_param_value("fmt") : "float";
  if (format != "float" && format != "rgba8")
    return Reply(res, 400, "fmt " + format + ": must be float or rgba8");
  const uint64_t mine = ++v->generation;
  o.interrupted = [v, mine]() -> vox::Status {
    if (v->generation.load() != mine) return vox::UnavailableError("a newer frame was requested");
    return vox::OkStatus();
  };
  std::lock_guard<std::mutex> lock(v->render_mutex);
  const double waited = handler.Seconds();
  if (v->generation.load() != mine) return Reply(res, 409, "superseded");
  vox::RenderJobOutput out;
  if (vox::Status s = vox::RunRenderJob(o, &out, v->session.get()); !s.ok()) {
    if (v->generation.load() != mine) return Reply(res, 409, s.ToString());
    const bool request = s.code() == vox::StatusCode::kInvalidArgument;
    return Reply(res, request ? 400 : 500, s.ToString());
  }
  json stats = json::parse(out.stats_json);
  json cam = stats["camera"];
  cam.erase("source");
  FrameRecord rec{cam.dump(), vox::SceneFileText(*scene), json(stats["lod"]["factor"]).dump()};
  {
    std::lock_guard<std::mutex> last(v->last_mutex);
    v->last_stats = out.stats_json;
    v->last = rec;
    v->have_last = true;
    if (req.get_param_value("refined") == "1") {
      v->last_refined = rec;
      v->have_refined = true;
    }
  }
  res.set_header("X-Vox-Lod", rec.lod);
  res.set_header("X-Vox-Camera", rec.camera);
  if (format == "rgba8") {
    res.set_content(PaintedRgba8(out.rgba, out.width, out.height, *scene),
                    "application/octet-stream");
  } else {
    // The float frame sent from the render's own buffer: a copy of a full-size frame (12 MiB
    // at 1024x768) costs a quarter of a second of page faults and copying on a busy machine.
    auto rgba = std::make_shared<std::vector<float>>(std::move(out.rgba));
    res.set_content_provider(rgba->size() * sizeof(float), "application/octet-stream",
                             [rgba](size_t offset, size_t length, httplib::DataSink& sink) {
                               return sink.write(
                                   reinterpret_cast<const char*>(rgba->data()) + offset, length);
                             });
  }
  // The panel, with the handler's time to here: the wait for an earlier
  // frame to stop, the render and the encoding.
  json panel = PanelOf(stats);
  panel["wait_ms"] = waited * 1e3;
  panel["server_ms"] = handler.Seconds() * 1e3;
  res.set_header("X-Vox-Panel", panel.dump());
}

// /probe?x=X&y=Y: the ray through image position (X, Y) (pixels of the last
// frame, from its top-left corner) in vox-probe's index space, and vox-probe's
// answer for it: {"ray": "ox oy oz dx dy dz" (C99 hex floats), "answer":
// "hit i j k t" | "miss", "voxel": [i, j, k] | null}.
void ServeProbe(Viewer* v, const httplib::Request& req, httplib::Response& res) {
  double x = 0, y = 0;
  if (!vox::ParseDouble(req.get_param_value("x"), &x) ||
      !vox::ParseDouble(req.get_param_value("y"), &y))
    return Reply(res, 400, "a probe request needs numbers x and y");
  std::string camera_text;
  {
    std::lock_guard<std::mutex> last(v->last_mutex);
    if (!v->have_last) return Reply(res, 409, "no frame yet");
    camera_text = v->last.camera;
  }
  auto cam = vox::ParseCamera(camera_text, "camera");
  if (!cam.ok()) return Reply(res, 500, cam.status().ToString());
  if (!(x >= 0 && y >= 0 && x <= cam->width && y <= cam->height))
    return Reply(res, 400,
                 "x and y must lie in the last frame (" + std::to_string(cam->width) + "x" +
                     std::to_string(cam->height) + ")");
  const vox::WorldRay w = cam->PixelRay(x, y);
  vox::Ray ray;
  ray.origin = v->grid.WorldToGrid(w.origin) + glm::dvec3(v->origin);  // grid -> index space
  ray.dir = v->grid.world_to_grid_linear * w.dir;
  char line[256];
  snprintf(line, sizeof line, "%a %a %a %a %a %a", ray.origin.x, ray.origin.y, ray.origin.z,
           ray.dir.x, ray.dir.y, ray.dir.z);
  vox::TraceCounters counters;
  std::lock_guard<std::mutex> lock(v->probe_mutex);
  auto hit = v->prober->Trace(ray, &counters);
  if (!hit.ok()) return Reply(res, 400, hit.status().ToString());
  json j{{"ray", line}, {"answer", "miss"}, {"voxel", nullptr}};
  if (*hit) {
    j["answer"] = vox::FormatHitLine(&(*hit)->voxel, (*hit)->t);
    j["voxel"] = {(*hit)->voxel.x, (*hit)->voxel.y, (*hit)->voxel.z};
  }
  res.set_content(j.dump(), "application/json");
}

void ServeSave(Viewer* v, httplib::Response& res) {
  FrameRecord rec;
  {
    std::lock_guard<std::mutex> last(v->last_mutex);
    if (!v->have_refined) return Reply(res, 409, "no refined frame yet");
    rec = v->last_refined;
  }
  auto saved = vox::SaveView(v->save, rec.camera, rec.scene, rec.lod);
  if (!saved.ok()) return Reply(res, 500, saved.status().ToString());
  res.set_content(*saved, "application/json");
}

// /info: what the page starts from: the store's name, whether it is a fog
// volume (the density control), and the scene (scene.json text).
std::string Info(const Viewer& v) {
  const vox::StoreMeta& m = v.session->stores.base->meta();
  return json{{"store", v.base.store_dir},
              {"fog", m.grid_class == vox::GridClass::kFogVolume},
              {"pyramid", v.session->stores.pyramid != nullptr},
              {"scene", json::parse(v.base_scene)}}
      .dump();
}

vox::Status OpenViewer(Viewer* v) {
  VOX_ASSIGN_OR_RETURN(v->session, vox::OpenRenderSession(v->base));
  vox::Store* store = v->session->stores.base.get();
  VOX_ASSIGN_OR_RETURN(v->prober, vox::Prober::OpenOn(store, vox::ProbeOptions{}));
  VOX_ASSIGN_OR_RETURN(v->grid, vox::GridTransform::FromMeta(store->meta()));
  v->origin = store->meta().origin;
  vox::Scene scene;
  if (!v->base.scene_path.empty()) {
    VOX_ASSIGN_OR_RETURN(scene, vox::LoadScene(v->base.scene_path));
  }
  v->base_scene = vox::SceneFileText(scene);
  v->save.store_dir = v->base.store_dir;
  v->save.scene_path = v->base.scene_path;
  return vox::CheckSaveTarget(v->save);
}

}  // namespace

static int RunTool(int argc, char** argv) {
  Viewer v;
  vox::RenderJobOptions& o = v.base;
  ViewFlags flags;
  std::vector<std::string> stores;
  const auto apply = [&](const std::string& flag, const std::string& value) {
    return ApplyViewFlag(&o, &flags, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &stores))
    return *exit_code;
  if (stores.size() != 1) return vox::UsageError(kCommandLine.program, "give exactly one store");
  o.store_dir = stores[0];
  o.exr_path.clear();
  o.keep_image = true;
  o.quiet = true;
  o.size_given = true;
  v.save.out_dir = flags.out_dir;
  if (vox::Status s = OpenViewer(&v); !s.ok()) {
    fprintf(stderr, "vox-view: %s\n", s.ToString().c_str());
    return 1;
  }

  httplib::Server server;
  server.Get("/", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(vox::kViewPage, "text/html; charset=utf-8");
  });
  server.Get("/frame", [&v](const httplib::Request& req, httplib::Response& res) {
    ServeFrame(&v, req, res);
  });
  server.Get("/probe", [&v](const httplib::Request& req, httplib::Response& res) {
    ServeProbe(&v, req, res);
  });
  server.Post("/save",
              [&v](const httplib::Request&, httplib::Response& res) { ServeSave(&v, res); });
  server.Get("/info", [&v](const httplib::Request&, httplib::Response& res) {
    res.set_content(Info(v), "application/json");
  });
  server.Get("/stats", [&v](const httplib::Request&, httplib::Response& res) {
    std::lock_guard<std::mutex> last(v.last_mutex);
    res.set_content(v.last_stats, "application/json");
  });
  server.Get("/camera", [&v](const httplib::Request&, httplib::Response& res) {
    std::lock_guard<std::mutex> last(v.last_mutex);
    res.set_content(v.have_last ? json::parse(v.last.camera).dump(2) + "\n" : "",
                    "application/json");
  });
  const int bound = flags.port == 0
                        ? server.bind_to_any_port("127.0.0.1")
                        : (server.bind_to_port("127.0.0.1", flags.port) ? flags.port : -1);
  if (bound < 0) {
    fprintf(stderr, "vox-view: cannot listen on 127.0.0.1:%d\n", flags.port);
    return 1;
  }
  printf("vox-view: http://127.0.0.1:%d/\n", bound);
  fflush(stdout);
  return server.listen_after_bind() ? 0 : 1;
}

int main(int argc, char** argv) { return vox::ToolMain("vox-view", argc, argv, RunTool); }
