#include "tools/view/saves.h"

#include <stdlib.h>
#include <sys/stat.h>

#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/util/atomic_file.h"
#include "core/util/path_identity.h"

namespace vox {
namespace {

using json = nlohmann::json;

// `s` as one shell word.
std::string ShellWord(const std::string& s) {
  bool plain = !s.empty();
  for (char c : s)
    plain = plain && (isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '/' ||
                      c == '-' || c == '+' || c == ',' || c == '=');
  if (plain) return s;
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string RealPath(const std::string& p) {
  std::unique_ptr<char, decltype(&free)> r(realpath(p.c_str(), nullptr), &free);
  return r ? std::string(r.get()) : std::string();
}

bool Exists(const std::string& p) {
  struct stat st;
  return lstat(p.c_str(), &st) == 0;
}

}  // namespace

Status CheckSaveTarget(const SaveTarget& t) {
  if (t.out_dir.empty()) return OkStatus();
  struct stat st;
  if (stat(t.out_dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
    return InvalidArgumentError("--out " + t.out_dir + ": not a directory");
  VOX_RETURN_IF_ERROR(CheckOutputPath(t.out_dir + "/view-001.cam.json").WithContext("--out"));
  const std::string out = RealPath(t.out_dir), store = RealPath(t.store_dir);
  if (!store.empty() && (out == store || out.rfind(store + "/", 0) == 0))
    return InvalidArgumentError("--out " + t.out_dir + ": inside the store " + t.store_dir +
                                " (an input)");
  return OkStatus();
}

std::string SceneFileText(const Scene& scene) {
  json j = json::parse(scene.ToJson());
  if (scene.default_lights) j.erase("lights");
  return j.dump(2) + "\n";
}

StatusOr<std::string> SaveView(const SaveTarget& t, const std::string& camera_json,
                               const std::string& scene_json, const std::string& lod) {
  std::string cam = "cam.json", scene = "scene.json", exr = "view.exr", script;
  std::vector<std::string> written;
  if (!t.out_dir.empty()) {
    // The first number none of whose names exists (the EXR the command
    // writes included).
    std::string base;
    for (int n = 1; n <= 9999 && base.empty(); ++n) {
      char name[32];
      snprintf(name, sizeof name, "/view-%03d", n);
      const std::string b = t.out_dir + name;
      if (!Exists(b + ".cam.json") && !Exists(b + ".scene.json") && !Exists(b + ".sh") &&
          !Exists(b + ".exr"))
        base = b;
    }
    if (base.empty())
      return ResourceExhaustedError("--out " + t.out_dir + ": view-001 .. view-9999 all taken");
    cam = base + ".cam.json";
    scene = base + ".scene.json";
    exr = base + ".exr";
    script = base + ".sh";
  }
  const std::string command = "vox-render " + ShellWord(t.store_dir) + " --cam " + ShellWord(cam) +
                              " --scene " + ShellWord(scene) + " --lod " + lod + " --float -o " +
                              ShellWord(exr);
  const std::string camera_text = json::parse(camera_json).dump(2) + "\n";
  if (!t.out_dir.empty()) {
    std::vector<NamedPath> inputs = StoreInputs(t.store_dir);
    if (!t.scene_path.empty()) inputs.push_back({"--scene", t.scene_path});
    VOX_RETURN_IF_ERROR(
        CheckDistinctPaths(inputs, {{"camera", cam}, {"scene", scene}, {"command", script}}));
    OutputGroup outputs;
    VOX_RETURN_IF_ERROR(outputs.AddBytes(cam, camera_text));
    VOX_RETURN_IF_ERROR(outputs.AddBytes(scene, scene_json));
    VOX_RETURN_IF_ERROR(outputs.AddBytes(script, "#!/bin/sh\n" + command + "\n"));
    VOX_RETURN_IF_ERROR(outputs.Commit());
    written = {cam, scene, script};
  }
  return json{{"camera", camera_text},
              {"scene", scene_json},
              {"lod", json::parse(lod)},
              {"command", command},
              {"written", written}}
      .dump();
}

}  // namespace vox
