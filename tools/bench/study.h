// vox-study: the accuracy study's timed loops (tools/bench/study.py drives them and makes the
// tables). Each part returns its measurements as JSON.
//
// Thread safety: thread-compatible; vox-study runs one part at a time.
#ifndef VOX_TOOLS_BENCH_STUDY_H_
#define VOX_TOOLS_BENCH_STUDY_H_

#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "render/camera.h"
#include "storage/store.h"

namespace vox::bench {

// The study's camera: at (0,0,3) looking at the unit sphere's centre, 40 degrees across.
Camera StudyCamera(int width, int height);
StatusOr<std::unique_ptr<Store>> OpenStudyStore(const std::string& dir);

struct PrecisionOptions {
  std::string store;  // the image's store (a small level-set sphere)
  int image = 384;    // its primary rays: image x image
  int per_family = 10000;
  int rounds = 5;
};
// Every traversal variant on the scenarios' ray families and the image's rays: refused first
// hits and single-thread time per ray.
StatusOr<nlohmann::json> RunPrecision(const PrecisionOptions& o);

struct PaperOptions {
  std::vector<std::string> stores;  // one store per grid
  std::vector<int> images;
  int threads = 2, rounds = 5;
};
// The paper's figures 7 and 8: single step against two steps with 4..7 first-step levels, whole
// frames and first hits only, alternating the splits round by round.
StatusOr<nlohmann::json> RunPaper(const PaperOptions& o);

}  // namespace vox::bench

#endif  // VOX_TOOLS_BENCH_STUDY_H_
