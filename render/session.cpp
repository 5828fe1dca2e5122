#include "render/session.h"

#include <malloc.h>
#include <sys/stat.h>

#include <algorithm>
#include <fstream>
#include <thread>
#include <utility>

#include "core/util/memory_budget.h"
#include "core/util/stopwatch.h"
#include "render/job_options.h"
#include "render/lod.h"

namespace vox {
namespace {

// The I/O threads reading ahead (--prefetch): each holds a run of bricks in
// its buffer and in the page cache (2 x kPrefetchRunBytes), so at most one
// per 32 MiB of budget, and a small budget keeps its memory for the cache.
int IoThreadsFor(const RenderJobOptions& options, const ProcessBudget& process) {
  if (!options.prefetch) return 0;
  return int(std::clamp<uint64_t>(process.bytes / (32 * kMiB), 1, uint64_t(options.io_threads)));
}

// An OpenVDB file given where a store belongs: an error that says how to
// make the store (OkStatus for anything else, which Store::Open judges).
Status RefuseVdbFile(const std::string& dir) {
  struct stat st;
  if (stat(dir.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return OkStatus();
  // OpenVDB files start with the magic number 0x56444220 (little-endian).
  char magic[4] = {};
  std::ifstream in(dir, std::ios::binary);
  in.read(magic, 4);
  const bool vdb_magic = in.gcount() == 4 && magic[0] == 0x20 && magic[1] == 0x42 &&
                         magic[2] == 0x44 && magic[3] == 0x56;
  const bool vdb_name = dir.size() > 4 && dir.compare(dir.size() - 4, 4, ".vdb") == 0;
  if (!vdb_magic && !vdb_name) return OkStatus();
  const std::string store = (vdb_name ? dir.substr(0, dir.size() - 4) : dir) + "_store";
  return InvalidArgumentError("'" + dir +
                              "' is an OpenVDB file, not a vox store: vox-render reads stores. "
                              "Make one first with\n  vox-ingest " + dir + " " + store +
                              "\nand render it: vox-render " + store + " ...");
}

// How a session's stores open.
OpenOptions SessionOpenOptions(const RenderJobOptions& options, const RenderSession& session) {
  OpenOptions open;
  // The budget bounds the cache (BudgetStore sets it once the resident top
  // is known); opening with it gives the cache its number of shards.
  open.cache_bytes = options.cache_mb > 0 ? options.cache_mb << 20 : session.process.bytes;
  open.io_threads = std::max(session.io_threads, 1);
  open.read_windows = options.read_windows;
  open.budget_bytes = session.process.bytes;
  return open;
}

}  // namespace

StatusOr<RenderStores> OpenRenderStores(const std::string& dir, std::optional<double> lod,
                                        const OpenOptions& open) {
  RenderStores stores;
  VOX_RETURN_IF_ERROR(RefuseVdbFile(dir));
  VOX_ASSIGN_OR_RETURN(stores.base, Store::Open(dir, open));
  stores.lod_default = !lod.has_value();
  if (lod) {
    stores.lod = *lod;
  } else if (HasLod(dir)) {
    stores.lod = kDefaultLodFactor;
  }
  if (stores.lod > 0) {
    auto pyramid = LodPyramid::Open(dir, *stores.base, open);
    if (!pyramid.ok())
      return pyramid.status().WithContext(stores.lod_default ? "level of detail (--lod 0: exact)"
                                                             : "--lod");
    stores.pyramid = std::move(pyramid).value();
    for (int l = 1; l <= stores.pyramid->max_level(); ++l)
      stores.levels.push_back(stores.pyramid->level(l));
  }
  // Open's scratch (the index blocks, as large as the resident top) is
  // free but stays in the main heap, which the render threads' allocator
  // arenas do not reuse: give it back so the budget's estimate holds.
  malloc_trim(0);
  return stores;
}

StatusOr<std::unique_ptr<RenderSession>> OpenRenderSession(const RenderJobOptions& options) {
  const Stopwatch open_time;
  auto session = std::make_unique<RenderSession>();
  session->anon_at_start = ReadProcessMemory().rss_anon;
  // Counted against an address space limit: the render threads, the main
  // thread, and --prefetch's scout and I/O threads.
  const int threads = options.threads > 0
                          ? options.threads
                          : int(std::max(1u, std::thread::hardware_concurrency()));
  const int job_threads = threads + 2 + (options.prefetch ? options.io_threads : 0);
  VOX_ASSIGN_OR_RETURN(session->process, ChooseProcessBudget(options.memory_bytes, job_threads));
  session->io_threads = IoThreadsFor(options, session->process);
  VOX_ASSIGN_OR_RETURN(session->stores, OpenRenderStores(options.store_dir, options.lod,
                                                         SessionOpenOptions(options, *session)));
  session->all_levels = session->stores.levels;
  session->open_seconds = open_time.Seconds();
  return session;
}

Status SetSessionLod(const RenderJobOptions& options, RenderSession* session) {
  RenderStores& stores = session->stores;
  stores.lod_default = !options.lod.has_value();
  stores.lod = options.lod ? *options.lod : stores.pyramid != nullptr ? kDefaultLodFactor : 0.0;
  if (stores.lod > 0 && stores.pyramid == nullptr) {
    auto pyramid =
        LodPyramid::Open(options.store_dir, *stores.base, SessionOpenOptions(options, *session));
    if (!pyramid.ok()) return pyramid.status().WithContext("--lod");
    stores.pyramid = std::move(pyramid).value();
    for (int l = 1; l <= stores.pyramid->max_level(); ++l)
      session->all_levels.push_back(stores.pyramid->level(l));
  }
  stores.levels = stores.lod > 0 ? session->all_levels : std::vector<Store*>{};
  return OkStatus();
}

}  // namespace vox
