// vox::OpenRenderStores and vox::OpenRenderSession: the stores a render
// reads, opened. A store and, when level of detail is in effect, its pyramid
// (RenderStores); and what stays open from one job to the next with the
// process budget chosen when it opened (RenderSession, vox-view's).
// RunRenderJob (render/job.h) opens a session for its run when not given
// one.
//
// Thread safety: thread-compatible.
#ifndef VOX_RENDER_SESSION_H_
#define VOX_RENDER_SESSION_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "render/job_options.h"
#include "storage/lod.h"
#include "storage/store.h"
#include "storage/store_budget.h"

namespace vox {

// The stores a render reads: the base and, when level of detail is in
// effect, its pyramid (storage/lod.h).
struct RenderStores {
  std::unique_ptr<Store> base;
  std::unique_ptr<LodPyramid> pyramid;
  std::vector<Store*> levels;  // pyramid levels 1 .., owned by `pyramid`
  double lod = 0.0;            // the factor in effect; 0: the exact frame
  bool lod_default = false;    // chosen by default, not by --lod
};

// Opens the store at `dir` and, when level of detail is in effect (`lod` >
// 0, or unset and the store has a pyramid: kDefaultLodFactor), its pyramid.
// vox-render and the benchmarks choose the same way. An OpenVDB file
// where the store belongs is refused with the vox-ingest command that makes
// one.
StatusOr<RenderStores> OpenRenderStores(const std::string& dir, std::optional<double> lod,
                                        const OpenOptions& open);

// What stays open from one job to the next (vox-view): the store, its
// pyramid when it has one (or --lod asked for it), their brick caches and the
// process budget chosen when it opened, from the opening options'
// store_dir, memory_bytes, cache_mb, threads, prefetch, io_threads and
// read_windows. A job given a session renders with these and its own
// camera, scene, size and --lod; a second identical frame reads no brick.
struct RenderSession {
  RenderStores stores;            // lod, lod_default and levels are set per job
  std::vector<Store*> all_levels; // the pyramid's levels, when it is open
  ProcessBudget process;
  uint64_t anon_at_start = 0;  // the process's anonymous memory before the stores opened
  int io_threads = 0;
  double open_seconds = 0.0;
};
StatusOr<std::unique_ptr<RenderSession>> OpenRenderSession(const RenderJobOptions& options);

// Sets the session's stores for a job's --lod (`options.lod`), as
// OpenRenderStores chooses: the pyramid is opened now if this job is the
// first to need it, and stays open with the session. RunRenderJob calls it
// before each job.
Status SetSessionLod(const RenderJobOptions& options, RenderSession* session);

}  // namespace vox

#endif  // VOX_RENDER_SESSION_H_
