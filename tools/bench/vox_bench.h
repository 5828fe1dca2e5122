// The parts of vox-bench (the accuracy/time study, docs/accuracy.md) and the rendering helpers they share.
// Each part measures, writes its tables (Markdown + CSV) and plots (SVG) into
// ctx.out_dir, and appends its Markdown section to `report`.
//
// Thread safety: thread-compatible; vox-bench runs the parts one at a time.
#ifndef VOX_TOOLS_BENCH_VOX_BENCH_H_
#define VOX_TOOLS_BENCH_VOX_BENCH_H_

#include <memory>
#include <string>

#include "core/util/status.h"
#include "render/camera.h"
#include "render/frame.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "storage/store.h"
#include "tools/bench/vox_bench_util.h"

namespace vox::bench {

// The camera of every study: at (0,0,3) looking at the unit sphere's centre,
// 40 degrees across (vdb_render -translate 0,0,3 -lookat 0,0,0 -fov 40).
Camera StudyCamera(int width, int height);
// vdb_render's camera options matching StudyCamera.
std::string VdbCameraArgs(int width, int height);
// One directional light without shadows and no specular (vdb_render's diffuse).
Scene DiffuseScene();

StatusOr<std::unique_ptr<Store>> OpenStore(const std::string& dir);

// Renders a whole frame with `threads` threads, without writing it.
StatusOr<FrameStats> TimeFrame(const Renderer& r, int threads);
// Renders the image into memory (mask: alpha > 0.5).
StatusOr<Image> RenderImage(const Renderer& r);

Status RunPaperPart(const RunContext& ctx, std::string* report);
Status RunPrecisionPart(const RunContext& ctx, std::string* report);
Status RunResolutionPart(const RunContext& ctx, std::string* report);
Status RunEffectsPart(const RunContext& ctx, std::string* report);
Status RunPeerPart(const RunContext& ctx, std::string* report);

// Writes NAME.md (provenance + table) and NAME.csv into ctx.out_dir.
Status WriteTable(const RunContext& ctx, const std::string& name, const std::string& title,
                  const Table& table, const std::string& notes = "");

}  // namespace vox::bench

#endif  // VOX_TOOLS_BENCH_VOX_BENCH_H_
