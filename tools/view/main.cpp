// vox-view: serves one local web page (127.0.0.1 only) that frames a vox
// store interactively. Each frame is rendered in-process by
// vox::RunRenderJob, the function vox-render runs, with the request's
// --view, --size and --lod applied by the option table vox-render parses
// its flags with (tools/common/options.h); so a frame and vox-render's EXR
// for the same flags are equal, bit for bit. A newer /frame request stops
// the one in flight (RenderJobOptions::interrupted).
#include <atomic>
#include <cstdio>
#include <mutex>
#include <string>
#include <vector>

#include <httplib.h>
#include <nlohmann/json.hpp>

#include "render/job.h"
#include "tools/common/cli.h"
#include "tools/common/flags.h"
#include "tools/common/options.h"
#include "tools/common/tool_main.h"
#include "tools/view/page.h"

namespace {

using vox::FlagArity;
// The render flags apply as vox-render's (vox::ApplyRenderFlag).
const vox::OptionSpec kViewOptions[] = {
    {"--port", FlagArity::kValue, "N", "Server", "the port on 127.0.0.1 (default 0: a free one)"},
    {"--scene", FlagArity::kValue, "scene.json", "Render", "as vox-render's --scene"},
    {"--memory-mb", FlagArity::kValue, "M", "Render", "as vox-render's --memory-mb"},
    {"--threads", FlagArity::kValue, "N", "Render", "as vox-render's --threads"},
};

vox::Status ApplyViewFlag(vox::RenderJobOptions* o, int* port, const std::string& flag,
                          const std::string& value) {
  if (flag != "--port") return vox::ApplyRenderFlag(o, flag, value);
  if (!vox::ParseInt(value, 0, 65535, port))
    return vox::InvalidArgumentError("--port " + value + ": must be in 0..65535");
  return vox::OkStatus();
}

const vox::CommandLineSpec kCommandLine{
    "vox-view",
    "vox-view STORE_DIR [options]",
    "Serves a web page on 127.0.0.1 that renders the vox store STORE_DIR as the mouse and the "
    "keyboard move the camera, and gives the vox-render command line of the view. Prints the "
    "page's address.",
    kViewOptions,
    "Only the page and its requests are served. Exit codes: 0 stopped, 1 failed, 2 bad "
    "command line.\n"};

struct Viewer {
  vox::RenderJobOptions base;
  std::atomic<uint64_t> generation{0};
  std::mutex render_mutex;  // one frame at a time: the memory budget is the process's
  std::mutex last_mutex;
  std::string last_stats = "{}";
};

// The request's query parameters as vox-render flags, over `base`.
vox::Status ApplyQuery(const httplib::Request& req, vox::RenderJobOptions* o) {
  const auto get = [&](const char* key) { return req.get_param_value(key); };
  if (!req.has_param("az") || !req.has_param("el") || !req.has_param("w") || !req.has_param("h"))
    return vox::InvalidArgumentError("a frame request needs az, el, w and h");
  VOX_RETURN_IF_ERROR(vox::ApplyRenderFlag(o, "--view", get("az") + "," + get("el")));
  VOX_RETURN_IF_ERROR(vox::ApplyRenderFlag(o, "--size", get("w") + "x" + get("h")));
  if (req.has_param("lod")) VOX_RETURN_IF_ERROR(vox::ApplyRenderFlag(o, "--lod", get("lod")));
  return vox::OkStatus();
}

void ServeFrame(Viewer* v, const httplib::Request& req, httplib::Response& res) {
  vox::RenderJobOptions o = v->base;
  if (vox::Status s = ApplyQuery(req, &o); !s.ok()) {
    res.status = 400;
    res.set_content(s.ToString() + "\n", "text/plain");
    return;
  }
  const uint64_t mine = ++v->generation;
  o.interrupted = [v, mine]() -> vox::Status {
    if (v->generation.load() != mine) return vox::UnavailableError("a newer frame was requested");
    return vox::OkStatus();
  };
  std::lock_guard<std::mutex> lock(v->render_mutex);
  if (v->generation.load() != mine) {
    res.status = 409;
    res.set_content("superseded\n", "text/plain");
    return;
  }
  vox::RenderJobOutput out;
  if (vox::Status s = vox::RunRenderJob(o, &out); !s.ok()) {
    res.status = v->generation.load() != mine ? 409 : 500;
    res.set_content(s.ToString() + "\n", "text/plain");
    return;
  }
  const nlohmann::json stats = nlohmann::json::parse(out.stats_json);
  {
    std::lock_guard<std::mutex> last(v->last_mutex);
    v->last_stats = out.stats_json;
  }
  res.set_header("X-Vox-Lod", nlohmann::json(stats["lod"]["factor"]).dump());
  res.set_header("X-Vox-Ms", std::to_string(stats["timings"].value("render_seconds", 0.0) * 1e3));
  res.set_content(std::string(reinterpret_cast<const char*>(out.rgba.data()),
                              out.rgba.size() * sizeof(float)),
                  "application/octet-stream");
}

// The last frame's camera, in cam.json's format (vox-render --cam).
std::string LastCamera(Viewer* v) {
  std::lock_guard<std::mutex> last(v->last_mutex);
  nlohmann::json stats = nlohmann::json::parse(v->last_stats);
  if (!stats.contains("camera")) return "";
  nlohmann::json cam = stats["camera"];
  cam.erase("source");
  return cam.dump(2) + "\n";
}

}  // namespace

static int RunTool(int argc, char** argv) {
  Viewer v;
  vox::RenderJobOptions& o = v.base;
  int port = 0;
  std::vector<std::string> stores;
  const auto apply = [&](const std::string& flag, const std::string& value) {
    return ApplyViewFlag(&o, &port, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &stores))
    return *exit_code;
  if (stores.size() != 1)
    return vox::UsageError(kCommandLine.program, "give exactly one store");
  o.store_dir = stores[0];
  o.exr_path.clear();
  o.keep_image = true;
  o.quiet = true;
  o.size_given = true;

  httplib::Server server;
  server.Get("/", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(vox::kViewPage, "text/html; charset=utf-8");
  });
  server.Get("/frame", [&v](const httplib::Request& req, httplib::Response& res) {
    ServeFrame(&v, req, res);
  });
  server.Get("/stats", [&v](const httplib::Request&, httplib::Response& res) {
    std::lock_guard<std::mutex> last(v.last_mutex);
    res.set_content(v.last_stats, "application/json");
  });
  server.Get("/camera", [&v](const httplib::Request&, httplib::Response& res) {
    res.set_content(LastCamera(&v), "application/json");
  });
  const int bound = port == 0 ? server.bind_to_any_port("127.0.0.1")
                              : (server.bind_to_port("127.0.0.1", port) ? port : -1);
  if (bound < 0) {
    fprintf(stderr, "vox-view: cannot listen on 127.0.0.1:%d\n", port);
    return 1;
  }
  printf("vox-view: http://127.0.0.1:%d/\n", bound);
  fflush(stdout);
  return server.listen_after_bind() ? 0 : 1;
}

int main(int argc, char** argv) { return vox::ToolMain("vox-view", argc, argv, RunTool); }
